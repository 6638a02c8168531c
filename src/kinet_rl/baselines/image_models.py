"""Forw and ForwInv: forward models in the feature space of a whole-image conv encoder.

Forw (paper Sec. 4, "Forward Model") encodes the scene image into one feature vector and learns
``z_t+1 = z_t + f_fwd(z_t, u_t)``. ForwInv (Agrawal et al., NeurIPS 2016) adds an inverse model
``u_t = f_inv(z_t, z_t+1)`` trained jointly. Neither representation ever sees object positions.

Object positions for evaluation come from a *motion probe* trained on detached features against
ground truth: given the features of two frames and an object's position in the first, it returns
that object's displacement. It is queried by position because object colours are random per
episode, so a whole-image feature cannot tell which object is "object 0"; the probe never sends
gradient into the encoder or forward model (see ``docs/baselines.md``).

Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 4 (Baselines); Agrawal et al., "Learning to
Poke by Poking", NeurIPS 2016.
"""

from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDictBase
from torch import Tensor, nn

from kinet_rl.baselines.encoders import ConvEncoder
from kinet_rl.baselines.imagination import feature_world_model
from kinet_rl.devices import model_device
from kinet_rl.envs.geometry import SceneGeometry
from kinet_rl.envs.workspace import workspace_for
from kinet_rl.keys import ACTION, GOAL_PIXELS, IMAGE_FEAT, OBJECT_POS, PIXELS
from kinet_rl.models.checkpointing import ConfigCheckpointMixin
from kinet_rl.models.interaction import ACTION_DIM, mlp
from kinet_rl.planners.world_model import (
    ModelCapabilities,
    PlanningDefaults,
    PushWorldModel,
    check_objective,
)


class MotionProbe(nn.Module):
    """Reads an object's displacement from the features of two frames, queried by its position.

    Args:
        feature_dim: ``D`` of the image features.
        hidden_dim: Hidden units.
        num_hidden: Hidden layers.
    """

    def __init__(self, feature_dim: int, hidden_dim: int = 128, num_hidden: int = 2) -> None:
        super().__init__()
        self.net = mlp(2 * feature_dim + 2, 2, hidden_dim, num_hidden)

    def forward(self, feat: Tensor, next_feat: Tensor, pos: Tensor) -> Tensor:
        """``[*B, D], [*B, D], [*B, N, 2]`` (workspace units) -> displacement ``[*B, N, 2]``."""
        pair = torch.cat([feat, next_feat - feat], dim=-1)
        pair = pair.unsqueeze(-2).expand(*pos.shape[:-1], -1)
        return self.net(torch.cat([pair, pos], dim=-1))


class ImageForwardModel(ConfigCheckpointMixin, nn.Module):
    """Forw baseline: conv encoder ``z = f_enc(I)``, forward MLP ``z' = z + f_fwd(z, u)``, probe.

    The encoder ends in a parameter-free LayerNorm, so features cannot shrink to a point; the
    contrastive term of :class:`~kinet_rl.baselines.losses.ImageForwardLoss` keeps them apart.

    Keys:
        :meth:`forward` reads ``ACTION`` ``[*B, 4]`` and ``IMAGE_FEAT`` ``[*B, D]`` or, if absent,
        ``PIXELS`` ``[*B, H, W, 3]`` (then writes ``IMAGE_FEAT``); writes ``("next", IMAGE_FEAT)``.

    Args:
        feature_dim: ``D`` of the image features.
        channels: Conv encoder width.
        num_down: Stride-2 conv layers of the encoder.
        hidden_dim: Hidden units of the forward (and inverse) MLP.
        num_hidden: Hidden layers of the forward (and inverse) MLP.
        probe_hidden_dim: Hidden units of the evaluation probe.
        task: ``"blocks"`` or ``"ycb"``; its workspace half-size is the probe's position unit.
    """

    checkpoint_format = "kinet_rl.ImageForwardModel/1"
    label = "Forw"
    #: Has an inverse model ``u = f_inv(z, z')`` (ForwInv), trained by ``loss_inv``.
    has_inverse_model = False
    capabilities = ModelCapabilities(
        observes=(PIXELS,), goal=(GOAL_PIXELS,), objectives=("feature_distance",)
    )
    planning = PlanningDefaults("feature_distance")

    def __init__(
        self,
        feature_dim: int = 64,
        channels: int = 32,
        num_down: int = 3,
        hidden_dim: int = 128,
        num_hidden: int = 3,
        probe_hidden_dim: int = 128,
        task: str = "blocks",
    ) -> None:
        super().__init__()
        self.config: dict[str, Any] = {
            "feature_dim": feature_dim,
            "channels": channels,
            "num_down": num_down,
            "hidden_dim": hidden_dim,
            "num_hidden": num_hidden,
            "probe_hidden_dim": probe_hidden_dim,
            "task": task,
        }
        self.position_scale = workspace_for(task).half_size
        self.encoder = ConvEncoder(feature_dim, channels, num_down, normalise=True)
        self.forward_model = mlp(feature_dim + ACTION_DIM, feature_dim, hidden_dim, num_hidden)
        self.probe = MotionProbe(feature_dim, probe_hidden_dim)

    def encode(self, pixels: Tensor) -> Tensor:
        """``[*B, H, W, 3]`` images -> features ``[*B, D]``."""
        return self.encoder(pixels)

    def predict(self, feat: Tensor, action: Tensor) -> Tensor:
        """Predicted next features ``[*B, D]`` from features ``[*B, D]`` and pushes ``[*B, 4]``."""
        if action.shape[-1] != ACTION_DIM or action.shape[:-1] != feat.shape[:-1]:
            raise ValueError(
                f"Expected action [*B, {ACTION_DIM}] matching features [*B, D]; got "
                f"{tuple(action.shape)} and {tuple(feat.shape)}."
            )
        return feat + self.forward_model(torch.cat([feat, action], dim=-1))

    def probe_motion(self, feat: Tensor, next_feat: Tensor, object_pos: Tensor) -> Tensor:
        """Probe's object displacement in metres ``[*B, N, 2]`` between two feature vectors."""
        return self.probe(feat, next_feat, object_pos / self.position_scale) * self.position_scale

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Predicts the next image features for ``ACTION`` (see the class ``Keys:``)."""
        feat = tensordict.get(IMAGE_FEAT, None)
        if feat is None:
            feat = self.encode(tensordict.get(PIXELS))
            tensordict.set(IMAGE_FEAT, feat)
        tensordict.set(("next", *IMAGE_FEAT), self.predict(feat, tensordict.get(ACTION)))
        return tensordict

    def world_model(self, objective: str | None = None) -> PushWorldModel:
        """This model as a ``torchrl.modules.WorldModel`` in image-feature space
        (:func:`~kinet_rl.baselines.imagination.feature_world_model`)."""
        name = check_objective(self.capabilities, objective or self.planning.objective, self.label)
        return feature_world_model(self, name)

    def object_rollout(self, geometry: SceneGeometry | None = None) -> FeatureObjectRollout:
        """The :class:`~kinet_rl.evaluation.forward.ObjectRollout` of this model.

        ``geometry`` is not needed: the probe works on the table in metres.
        """
        return FeatureObjectRollout(self)


class ImageForwardInverseModel(ImageForwardModel):
    """ForwInv baseline: :class:`ImageForwardModel` plus an inverse model ``u = f_inv(z, z')``.

    Reference: Agrawal et al., "Learning to Poke by Poking", NeurIPS 2016 (continuous actions
    regressed here instead of their discretised classification).

    Args:
        See :class:`ImageForwardModel`.
    """

    checkpoint_format = "kinet_rl.ImageForwardInverseModel/1"
    label = "ForwInv"
    has_inverse_model = True

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        dim, cfg = self.config["feature_dim"], self.config
        self.inverse_model = mlp(2 * dim, ACTION_DIM, cfg["hidden_dim"], cfg["num_hidden"])

    def infer_action(self, feat: Tensor, next_feat: Tensor) -> Tensor:
        """Inferred push ``[*B, 4]`` between features ``[*B, D]`` and next features ``[*B, D]``."""
        return self.inverse_model(torch.cat([feat, next_feat], dim=-1))


class FeatureObjectRollout:
    """:class:`~kinet_rl.evaluation.forward.ObjectRollout` of Forw/ForwInv.

    Features are rolled forward open-loop from the start image; after each push every object
    moves by the probe's displacement between the previous and the predicted features, queried at
    the object's previous (predicted) position, starting from the ground-truth start positions.
    """

    def __init__(self, model: ImageForwardModel) -> None:
        self.model = model

    @torch.no_grad()
    def __call__(self, start: TensorDictBase, actions: Tensor) -> Tensor:
        out_device = actions.device
        device = model_device(self.model)
        start, actions = start.to(device), actions.to(device)
        feat = self.model.encode(start[PIXELS])
        pos = start[OBJECT_POS]
        steps = []
        for h in range(actions.shape[1]):
            next_feat = self.model.predict(feat, actions[:, h])
            pos = pos + self.model.probe_motion(feat, next_feat, pos)
            steps.append(pos)
            feat = next_feat
        return torch.stack(steps, dim=1).to(out_device)
