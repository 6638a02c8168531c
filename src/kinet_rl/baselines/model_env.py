"""Baselines as TorchRL model envs, and the MPC controller that plans with them.

"For all baseline models, we perform MPC directly on the distance to the goal" (KINet, Sec. 5):

* IN / IN-full / VisIN (:class:`ObjectModelEnv`): state = ground-truth object positions (+ IN-full's
  yaw and shape features, VisIN's crop features of the current image, carried over while
  imagining); reward = minus the mean distance
  (metres) of the predicted object positions to the ground-truth goal positions.
* Forw / ForwInv (:class:`FeatureModelEnv`): state = the whole-image feature ``z``; reward =
  ``-|z_hat - z_goal|^2`` with ``z_goal`` the feature of the goal image.
* V-CDN (:class:`KeypointGraphModelEnv`): state = the detected keypoints and the graph inferred
  from them (carried over while imagining); reward = minus the mean distance of the predicted
  keypoints to the goal image's keypoints (index-matched, image units).

Both share :class:`~kinet_rl.planners.StateModelEnv` with the oracle's and KINet's model envs;
the rearrangement evaluation plans over them with :class:`~kinet_rl.planners.GraphMPCPlanner`
(method ``model_mpc``).
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torch import Tensor, nn

from kinet_rl.baselines.image_models import ImageForwardModel
from kinet_rl.baselines.object_models import ObjectInteractionModel
from kinet_rl.baselines.vcdn import VCDNWorldModel
from kinet_rl.keys import (
    ACTION,
    GOAL_IMAGE_FEAT,
    GOAL_KP_POS,
    GOAL_OBJECT_POS,
    IMAGE_FEAT,
    KP_EDGE_TYPE,
    KP_POS,
    OBJECT_FEAT,
    OBJECT_POS,
    PIXELS,
    STEP_REWARD,
)
from kinet_rl.planners.model_env import StateModelEnv, check_goal_image


class _PositionStep(nn.Module):
    """One imagined push of positions with a carried context (IN-full/VisIN's node features,
    V-CDN's graph); reward: minus the mean distance of the predicted positions to the goal's."""

    def __init__(self, model: nn.Module, predict: Callable[[Tensor, Tensor, Tensor], Tensor]):
        super().__init__()
        self.model = model  # holds the parameters that ``predict`` uses
        self.predict = predict

    def forward(
        self, pos: Tensor, context: Tensor, action: Tensor, goal: Tensor
    ) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        nxt = self.predict(pos, context, action)
        reward = -(nxt - goal).norm(dim=-1).mean(-1, keepdim=True)  # [*B, 1]
        return nxt, context, reward, goal


class _FeatureStep(nn.Module):
    def __init__(self, model: ImageForwardModel) -> None:
        super().__init__()
        self.model = model

    def forward(self, feat: Tensor, action: Tensor, goal: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        nxt = self.model.predict(feat, action)
        reward = -(nxt - goal).pow(2).sum(-1, keepdim=True)  # [*B, 1]
        return nxt, reward, goal


class ObjectModelEnv(StateModelEnv):
    """Imagined pushes with IN, IN-full or VisIN on ground-truth object positions.

    Keys:
        State/observation: ``OBJECT_POS`` ``[*B, N, 2]`` metres, ``OBJECT_FEAT`` ``[*B, N, F]``
        (the model's node features of the current state, carried over: IN-full's yaw and shape,
        VisIN's crop features of the current image; ``F = 0`` for IN) and
        ``GOAL_OBJECT_POS`` ``[*B, N, 2]``. Action ``[*B, 4]`` in ``[-1, 1]``. Reward ``[*B, 1]``:
        minus the mean distance (metres) of the predicted positions to the goal positions.

    Args:
        model: A (trained) :class:`ObjectInteractionModel`, :class:`FullStateInteractionModel`
            or :class:`VisualInteractionModel`.
    """

    def __init__(self, model: ObjectInteractionModel) -> None:
        step = TensorDictModule(
            _PositionStep(model, model.predict),
            in_keys=[OBJECT_POS, OBJECT_FEAT, ACTION, GOAL_OBJECT_POS],
            out_keys=[OBJECT_POS, OBJECT_FEAT, STEP_REWARD, GOAL_OBJECT_POS],
        )
        n, f = model.num_objects, model.node_feature_dim
        super().__init__(step, {OBJECT_POS: (n, 2), OBJECT_FEAT: (n, f), GOAL_OBJECT_POS: (n, 2)})
        self.model = model

    @torch.no_grad()
    def observe(
        self, pixels: Tensor, object_pos: Tensor, goal_pos: Tensor, **state: Tensor
    ) -> TensorDict:
        """The start state: positions, their node features and the goal.

        Args:
            pixels: uint8 ``[*B, H, W, 3]`` current images (used by VisIN only).
            object_pos: ``[*B, N, 2]`` ground-truth positions, metres.
            goal_pos: ``[*B, N, 2]`` goal positions, metres (or ``[N, 2]`` for all).
            state: the model's ``state_keys`` entries ``[*B, N, ...]`` (IN-full: ``object_yaw``
                and ``object_shape``).
        """
        missing = [key for key in self.model.state_keys if key not in state]
        if missing:
            raise KeyError(
                f"{type(self.model).__name__} plans from {list(self.model.state_keys)} as well; "
                f"pass {missing} to observe() (the env observation has them)."
            )
        pixels, object_pos = pixels.to(self.device), object_pos.to(self.device).float()
        batch = object_pos.shape[:-2]
        entries = {PIXELS: pixels, OBJECT_POS: object_pos}
        entries.update({key: state[key].to(self.device).float() for key in self.model.state_keys})
        flat = TensorDict(
            {key: value.reshape(-1, *value.shape[len(batch) :]) for key, value in entries.items()},
            batch_size=[batch.numel()],
        )
        self.model.eval()
        feat = self.model.node_features(flat).reshape(*batch, *object_pos.shape[-2:-1], -1)
        goal = goal_pos.to(self.device).float().expand_as(object_pos)
        return TensorDict(
            {OBJECT_POS: object_pos, OBJECT_FEAT: feat, GOAL_OBJECT_POS: goal},
            batch_size=batch,
            device=self.device,
        )


class FeatureModelEnv(StateModelEnv):
    """Imagined pushes with Forw or ForwInv in the feature space of the whole image.

    Keys:
        State/observation: ``IMAGE_FEAT`` ``[*B, D]`` and ``GOAL_IMAGE_FEAT`` ``[*B, D]``. Action
        ``[*B, 4]`` in ``[-1, 1]``. Reward ``[*B, 1]``: ``-|z_hat - z_goal|^2``.

    Args:
        model: A (trained) :class:`ImageForwardModel` or :class:`ImageForwardInverseModel`.
    """

    def __init__(self, model: ImageForwardModel) -> None:
        step = TensorDictModule(
            _FeatureStep(model),
            in_keys=[IMAGE_FEAT, ACTION, GOAL_IMAGE_FEAT],
            out_keys=[IMAGE_FEAT, STEP_REWARD, GOAL_IMAGE_FEAT],
        )
        d = model.config["feature_dim"]
        super().__init__(step, {IMAGE_FEAT: (d,), GOAL_IMAGE_FEAT: (d,)})
        self.model = model

    @torch.no_grad()
    def observe(self, pixels: Tensor, goal_pixels: Tensor) -> TensorDict:
        """The start state: features of ``pixels`` ``[*B, H, W, 3]`` and of the goal image."""
        check_goal_image(pixels, goal_pixels)
        self.model.eval()
        feat = self.model.encode(pixels.to(self.device))
        goal = self.model.encode(goal_pixels.to(self.device)).expand_as(feat)
        return TensorDict(
            {IMAGE_FEAT: feat, GOAL_IMAGE_FEAT: goal},
            batch_size=feat.shape[:-1],
            device=self.device,
        )


class KeypointGraphModelEnv(StateModelEnv):
    """Imagined pushes with V-CDN on the keypoints of the current image and their inferred graph.

    Keys:
        State/observation: ``KP_POS`` ``[*B, K, 2]``, ``KP_EDGE_TYPE`` ``[*B, K, K - 1, C]``
        (inferred from the current image's keypoints, carried over) and ``GOAL_KP_POS``
        ``[*B, K, 2]`` (the goal image's keypoints). Action ``[*B, 4]`` in ``[-1, 1]``. Reward
        ``[*B, 1]``: minus the mean over keypoints of ``|x_hat_k - g_k|`` (image units), keypoint
        ``k`` against the goal's keypoint ``k`` (the detector's channels are consistent).

    Args:
        model: A (trained) :class:`VCDNWorldModel`.
    """

    def __init__(self, model: VCDNWorldModel) -> None:
        step = TensorDictModule(
            _PositionStep(model, model.dynamics),
            in_keys=[KP_POS, KP_EDGE_TYPE, ACTION, GOAL_KP_POS],
            out_keys=[KP_POS, KP_EDGE_TYPE, STEP_REWARD, GOAL_KP_POS],
        )
        k, c = model.config["num_keypoints"], model.config["num_edge_types"]
        shapes = {KP_POS: (k, 2), KP_EDGE_TYPE: (k, k - 1, c), GOAL_KP_POS: (k, 2)}
        super().__init__(step, shapes)
        self.model = model

    @torch.no_grad()
    def observe(self, pixels: Tensor, goal_pixels: Tensor) -> TensorDict:
        """The start state: keypoints and graph of ``pixels`` ``[*B, H, W, 3]``, goal keypoints."""
        check_goal_image(pixels, goal_pixels)
        self.model.eval()
        pos = self.model.keypoints(pixels.to(self.device))
        edge_types, _ = self.model.inference(pos)
        goal = self.model.keypoints(goal_pixels.to(self.device)).expand_as(pos)
        return TensorDict(
            {KP_POS: pos, KP_EDGE_TYPE: edge_types, GOAL_KP_POS: goal},
            batch_size=pos.shape[:-2],
            device=self.device,
        )


def make_baseline_env(
    model: nn.Module,
) -> ObjectModelEnv | FeatureModelEnv | KeypointGraphModelEnv:
    """The model env of a baseline: :class:`ObjectModelEnv` (IN/IN-full/VisIN), :class:`FeatureModelEnv`
    (Forw/ForwInv) or :class:`KeypointGraphModelEnv` (V-CDN)."""
    if isinstance(model, ObjectInteractionModel):
        return ObjectModelEnv(model)
    if isinstance(model, ImageForwardModel):
        return FeatureModelEnv(model)
    if isinstance(model, VCDNWorldModel):
        return KeypointGraphModelEnv(model)
    raise TypeError(
        f"No baseline model env for {type(model).__name__}; model_mpc plans with IN, IN-full, VisIN, "
        "Forw, ForwInv or V-CDN (use the kinet_graph / kinet_keypoints methods for KINet)."
    )
