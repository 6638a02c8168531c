"""KINet world model: keypoint detector, reconstructor and interaction net behind TensorDict keys.

Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 3.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import torch
from tensordict import TensorDictBase
from torch import Tensor

from kinet_rl.keys import (
    ACTION,
    FUTURE_ACTION,
    FUTURE_PIXELS,
    GOAL_PIXELS,
    KP_FEAT,
    KP_NODE_EMB,
    KP_POS,
    NEXT_PIXELS,
    PIXELS,
    PIXELS_0,
)
from kinet_rl.models.checkpointing import ConfigCheckpointMixin
from kinet_rl.models.imagination import KEYPOINT_OBJECTIVES, keypoint_graph_world_model
from kinet_rl.models.interaction import GraphPrediction, KeypointInteractionNet
from kinet_rl.models.keypoint_model import KeypointWorldModel
from kinet_rl.models.keypoints import KeypointDetector, KeypointReconstructor, pixels_to_input
from kinet_rl.planners.world_model import (
    ModelCapabilities,
    PlanningDefaults,
    PushWorldModel,
    check_objective,
)

log = logging.getLogger(__name__)

CHECKPOINT_FORMAT = "kinet_rl.KINetWorldModel/1"


@dataclass
class TransitionOutputs:
    """Everything the KINet losses need for a batch of ``B`` transitions ``(I_0, I_t, u, I_t+1)``.

    Attributes:
        pos: ``[B, K, 2]`` detected ``x_t`` (with gradient to the detector).
        next_pos: ``[B, K, 2]`` detected ``x_t+1`` (no gradient: a forward-model target).
        next_feat: ``[B, K, D]`` detected ``phi_t+1`` (no gradient).
        reconstruction: ``[B, H, W, 3]`` ``f_rec(I_0, I_t)`` in the centred space (paper Sec. 3.1).
        target: ``[B, H, W, 3]`` ``I_t`` in the same centred space.
        prediction: Interaction-net output from the detached ``x_t``, the features ``phi_t``
            (trained by the forward and contrastive losses) and the action.
        rollout: ``[B, H - 1, K, 2]`` keypoints predicted open-loop for the pushes after
            ``u_t`` (from ``x_hat_t+1`` on, features carried over), when the batch has them.
        rollout_target: ``[B, H - 1, K, 2]`` keypoints detected in those frames (no gradient).
    """

    pos: Tensor
    next_pos: Tensor
    next_feat: Tensor
    reconstruction: Tensor
    target: Tensor
    prediction: GraphPrediction
    rollout: Tensor | None = None
    rollout_target: Tensor | None = None


class KINetWorldModel(ConfigCheckpointMixin, KeypointWorldModel):
    """Keypoint detector ``f_kp``, reconstructor ``f_rec`` and interaction net ``f_fwd``.

    Keypoints fed to the interaction net are detached, so forward-model losses never move the
    detector's keypoints (paper Sec. 3.5, after Minderer et al. 2019); the keypoint features
    ``phi`` are learnt by the forward and contrastive losses (``feature_grad``).

    Keys:
        :meth:`forward` reads ``ACTION`` ``[*B, 4]`` and either ``KP_POS`` ``[*B, K, 2]`` +
        ``KP_FEAT`` ``[*B, K, D]`` or, if those are absent, ``PIXELS`` ``[*B, H, W, 3]`` (then
        writes ``KP_POS``/``KP_FEAT``). It writes ``KP_NODE_EMB`` ``[*B, K, E]`` and the
        predictions ``("next", KP_POS)``, ``("next", KP_FEAT)`` (appearance carried over) and
        ``("next", KP_NODE_EMB)``.

    Args:
        num_keypoints: ``K`` detected keypoints.
        feat_dim: ``D`` of each keypoint's visual feature.
        channels: Detector/reconstructor conv width.
        blob_std: Gaussian blob std of the transport step, in ``[-1, 1]`` units.
        embed_dim: ``E`` of graph node/edge embeddings.
        hidden_dim: Hidden units of the graph MLPs.
        num_hidden: Hidden layers of the graph MLPs.
        num_rounds: ``L`` message-passing rounds.
        deterministic: Ablation: fully connected graph and no KL.
        feature_grad: ``"head"`` (the feature projection learns from the forward and contrastive
            losses), ``"encoder"`` (the detector's encoder too) or ``"none"`` (fixed random
            features, an ablation); see :class:`KeypointDetector`.
        action_frame: ``"table"`` or ``"learned"``: the frame of the push in the node update (see
            :class:`KeypointInteractionNet`).
        heatmap_stride: 4 (16x16 heatmaps for 64 px images) or 2 (32x32); see
            :class:`KeypointDetector`.
    """

    checkpoint_format = CHECKPOINT_FORMAT
    model_file = "kinet.pt"
    label = "KINet"
    capabilities = ModelCapabilities(
        observes=(PIXELS,),
        goal=(GOAL_PIXELS,),
        objectives=KEYPOINT_OBJECTIVES,
        any_object_count=True,
        reconstructs=True,
        keypoints=True,
    )
    #: Index-matched keypoint L2 at the validated budget: chosen on validation episodes
    #: (docs/results.md); a checkpoint stores its own.
    planning = PlanningDefaults("keypoints_l2")

    def __init__(
        self,
        num_keypoints: int = 6,
        feat_dim: int = 16,
        channels: int = 32,
        blob_std: float = 0.1,
        embed_dim: int = 64,
        hidden_dim: int = 128,
        num_hidden: int = 3,
        num_rounds: int = 3,
        deterministic: bool = False,
        feature_grad: str = "head",
        action_frame: str = "table",
        heatmap_stride: int = 4,
    ) -> None:
        super().__init__()
        self.config: dict[str, Any] = {
            "num_keypoints": num_keypoints,
            "feat_dim": feat_dim,
            "channels": channels,
            "blob_std": blob_std,
            "embed_dim": embed_dim,
            "hidden_dim": hidden_dim,
            "num_hidden": num_hidden,
            "num_rounds": num_rounds,
            "deterministic": deterministic,
            "feature_grad": feature_grad,
            "action_frame": action_frame,
            "heatmap_stride": heatmap_stride,
        }
        self.detector = KeypointDetector(
            num_keypoints, feat_dim, channels, feature_grad, heatmap_stride
        )
        self.reconstructor = KeypointReconstructor(channels, blob_std)
        self.interaction = KeypointInteractionNet(
            feat_dim, embed_dim, hidden_dim, num_hidden, num_rounds, deterministic, action_frame
        )

    def world_model(self, objective: str | None = None, fast: bool = True) -> PushWorldModel:
        """KINet as a ``torchrl.modules.WorldModel`` planning with ``objective`` (default: its
        ``planning.objective``); see :func:`~kinet_rl.models.imagination.keypoint_graph_world_model`."""
        name = check_objective(self.capabilities, objective or self.planning.objective, self.label)
        return keypoint_graph_world_model(self.detector, self.interaction, name, fast)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Predicts the next keypoints for ``ACTION`` (see the class ``Keys:``)."""
        pos = tensordict.get(KP_POS, None)
        feat = tensordict.get(KP_FEAT, None)
        if pos is None or feat is None:
            pixels = tensordict.get(PIXELS, None)
            if pixels is None:
                raise KeyError(
                    f"KINetWorldModel needs {KP_POS!r} and {KP_FEAT!r} or {PIXELS!r} in the input; "
                    "add a KeypointTransform to the env or pass images."
                )
            pos, feat = self.detector(pixels)
            tensordict.set(KP_POS, pos)
            tensordict.set(KP_FEAT, feat)
        prediction = self.interaction(pos.detach(), feat.detach(), tensordict.get(ACTION))
        tensordict.set(KP_NODE_EMB, prediction.nodes)
        tensordict.set(("next", *KP_POS), prediction.next_pos)
        tensordict.set(("next", *KP_FEAT), feat.detach())
        tensordict.set(("next", *KP_NODE_EMB), prediction.next_nodes)
        return tensordict

    def transition(self, tensordict: TensorDictBase) -> TransitionOutputs:
        """Runs detector, reconstructor and interaction net on a batch of transitions.

        Args:
            tensordict: ``[B]`` batch with ``PIXELS_0``, ``PIXELS``, ``ACTION`` and
                ``("next", PIXELS)``; images ``[B, H, W, 3]`` uint8 or float in ``[0, 1]``.
        """
        needed = (PIXELS_0, PIXELS, NEXT_PIXELS, ACTION)
        missing = [key for key in needed if tensordict.get(key, None) is None]
        if missing:
            raise KeyError(
                f"A KINet training batch needs {PIXELS_0!r}, {PIXELS!r}, ('next', {PIXELS!r}) and "
                f"{ACTION!r}; missing: {missing}. Sample batches with PushDataset.sample()."
            )
        first, current, following, action = (tensordict.get(key) for key in needed)
        if not first.shape == current.shape == following.shape or first.dim() != 4:
            raise ValueError(
                "pixels_0, pixels and ('next', 'pixels') must share one [B, H, W, 3] shape; got "
                f"{tuple(first.shape)}, {tuple(current.shape)}, {tuple(following.shape)}."
            )
        batch = first.shape[0]
        # I_0 and I_t+1 in one pass without gradient: I_t+1 is only a forward-model target
        # (detached anyway, paper Sec. 3.5); dropping the gradient through I_0's features made
        # a training step ~1.2x faster and learnt as well (docs/kinet.md, "Training speed", and
        # tests/integration/test_models_learning.py, 3 seeds). The detector learns from I_t.
        with torch.no_grad():
            source, following_enc = self.detector.encode(torch.cat([first, following])).split(batch)
        observed = self.detector.encode(current)
        reconstruction = self.reconstructor(source, observed)
        target = pixels_to_input(current).permute(0, 2, 3, 1)
        prediction = self.interaction(observed.pos.detach(), observed.feat, action)
        pos, next_pos, next_feat = observed.pos, following_enc.pos, following_enc.feat
        out = TransitionOutputs(pos, next_pos, next_feat, reconstruction, target, prediction)
        if tensordict.get(FUTURE_PIXELS, None) is not None:
            out.rollout, out.rollout_target = self._rollout(
                prediction.next_pos, observed.feat, tensordict
            )
        return out

    def _rollout(
        self, pos: Tensor, feat: Tensor, tensordict: TensorDictBase
    ) -> tuple[Tensor, Tensor]:
        """Open-loop keypoints for the batch's future pushes, and the detected ones (targets)."""
        frames, actions = tensordict.get(FUTURE_PIXELS), tensordict.get(FUTURE_ACTION)
        with torch.no_grad():
            target, _ = self.detector(frames)  # [B, H - 1, K, 2]
        return self._roll(pos, feat, actions), target

    def _roll(self, pos: Tensor, feat: Tensor, actions: Tensor) -> Tensor:
        """Keypoints ``[B, L, K, 2]`` after each of the pushes ``[B, L, 4]``, features carried."""
        steps = []
        for h in range(actions.shape[1]):
            pos = self.interaction(pos, feat, actions[:, h]).next_pos
            steps.append(pos)
        return torch.stack(steps, dim=1)

    @torch.no_grad()
    def rollout_keypoints(self, pixels: Tensor, actions: Tensor) -> Tensor:
        """Detected keypoints of ``pixels`` ``[B, H, W, 3]`` and the predicted ones after each
        push ``[B, L, 4]``: ``[B, L + 1, K, 2]``."""
        pos, feat = self.detector(pixels)
        return torch.cat([pos.unsqueeze(1), self._roll(pos, feat, actions)], dim=1)
