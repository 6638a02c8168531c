"""Baselines as TorchRL model envs, and the MPC controller that plans with them.

"For all baseline models, we perform MPC directly on the distance to the goal" (KINet, Sec. 5):

* IN / VisIN (:class:`ObjectModelEnv`): state = ground-truth object positions (+ VisIN's crop
  features of the current image, carried over while imagining); reward = minus the mean distance
  (metres) of the predicted object positions to the ground-truth goal positions.
* Forw / ForwInv (:class:`FeatureModelEnv`): state = the whole-image feature ``z``; reward =
  ``-|z_hat - z_goal|^2`` with ``z_goal`` the feature of the goal image.

:class:`BaselineMPCController` runs :class:`~kinet_rl.planners.GraphMPCPlanner` over either env
and follows the ``Controller`` protocol of :mod:`kinet_rl.control.rearrange`, so the shared
rearrangement evaluation can run a baseline checkpoint (method ``model_mpc``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule
from torch import Tensor, nn
from torchrl.data import Bounded, Composite, Unbounded
from torchrl.envs.model_based import ModelBasedEnvBase

from kinet_rl.baselines.image_models import IMAGE_FEAT, ImageForwardModel
from kinet_rl.baselines.object_models import ObjectInteractionModel
from kinet_rl.keys import ACTION, GOAL_IMAGE_FEAT, GOAL_OBJECT_POS, OBJECT_FEAT, OBJECT_POS, PIXELS
from kinet_rl.planners import GraphMPCPlanner

if TYPE_CHECKING:
    from kinet_rl.control.rearrange import Episode


class _ObjectStep(nn.Module):
    def __init__(self, model: ObjectInteractionModel) -> None:
        super().__init__()
        self.model = model

    def forward(
        self, pos: Tensor, feat: Tensor, action: Tensor, goal: Tensor
    ) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        nxt = self.model.predict(pos, feat, action)
        reward = -(nxt - goal).norm(dim=-1).mean(-1, keepdim=True)  # [*B, 1] mean metres
        return nxt, feat, reward, goal


class _FeatureStep(nn.Module):
    def __init__(self, model: ImageForwardModel) -> None:
        super().__init__()
        self.model = model

    def forward(self, feat: Tensor, action: Tensor, goal: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        nxt = self.model.predict(feat, action)
        reward = -(nxt - goal).pow(2).sum(-1, keepdim=True)  # [*B, 1]
        return nxt, reward, goal


class _BaselineModelEnv(ModelBasedEnvBase):
    """Shared construction: a TD step module, a full state spec, a 4-d push action in [-1, 1]."""

    def __init__(self, step: TensorDictModule, state_shapes: Mapping[Any, tuple[int, ...]]) -> None:
        device = next(step.parameters(), torch.empty(0)).device
        super().__init__(step, device=device, batch_size=torch.Size([]))
        state = Composite(
            {key: Unbounded(shape, device=device) for key, shape in state_shapes.items()},
            device=device,
        )
        self.observation_spec = state.clone()
        self.state_spec = state
        self.action_spec = Bounded(-1.0, 1.0, (4,), device=device)
        self.reward_spec = Unbounded((1,), device=device)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        keys = list(self.state_spec.keys(True, True))
        if tensordict is None or any(key not in tensordict.keys(True) for key in keys):
            raise KeyError(
                f"{type(self).__name__}.reset needs a tensordict with the state keys {keys}; "
                "env.observe(...) builds it from an observation and a goal."
            )
        return tensordict.select(*keys).clone()


class ObjectModelEnv(_BaselineModelEnv):
    """Imagined pushes with IN or VisIN on ground-truth object positions.

    Keys:
        State/observation: ``OBJECT_POS`` ``[*B, N, 2]`` metres, ``OBJECT_FEAT`` ``[*B, N, F]``
        (VisIN crop features of the current image, carried over; ``F = 0`` for IN) and
        ``GOAL_OBJECT_POS`` ``[*B, N, 2]``. Action ``[*B, 4]`` in ``[-1, 1]``. Reward ``[*B, 1]``:
        minus the mean distance (metres) of the predicted positions to the goal positions.

    Args:
        model: A (trained) :class:`ObjectInteractionModel` or :class:`VisualInteractionModel`.
    """

    def __init__(self, model: ObjectInteractionModel) -> None:
        step = TensorDictModule(
            _ObjectStep(model),
            in_keys=[OBJECT_POS, OBJECT_FEAT, ACTION, GOAL_OBJECT_POS],
            out_keys=[OBJECT_POS, OBJECT_FEAT, "reward", GOAL_OBJECT_POS],
        )
        n, f = model.num_objects, model.node_feature_dim
        super().__init__(step, {OBJECT_POS: (n, 2), OBJECT_FEAT: (n, f), GOAL_OBJECT_POS: (n, 2)})
        self.model = model

    @torch.no_grad()
    def observe(self, pixels: Tensor, object_pos: Tensor, goal_pos: Tensor) -> TensorDict:
        """The start state: positions, their node features from ``pixels`` and the goal.

        Args:
            pixels: uint8 ``[*B, H, W, 3]`` current images (used by VisIN only).
            object_pos: ``[*B, N, 2]`` ground-truth positions, metres.
            goal_pos: ``[*B, N, 2]`` goal positions, metres (or ``[N, 2]`` for all).
        """
        pixels, object_pos = pixels.to(self.device), object_pos.to(self.device).float()
        batch = object_pos.shape[:-2]
        flat = TensorDict(
            {
                PIXELS: pixels.reshape(-1, *pixels.shape[-3:]),
                OBJECT_POS: object_pos.reshape(-1, *object_pos.shape[-2:]),
            },
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


class FeatureModelEnv(_BaselineModelEnv):
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
            out_keys=[IMAGE_FEAT, "reward", GOAL_IMAGE_FEAT],
        )
        d = model.config["feature_dim"]
        super().__init__(step, {IMAGE_FEAT: (d,), GOAL_IMAGE_FEAT: (d,)})
        self.model = model

    @torch.no_grad()
    def observe(self, pixels: Tensor, goal_pixels: Tensor) -> TensorDict:
        """The start state: features of ``pixels`` ``[*B, H, W, 3]`` and of the goal image."""
        if goal_pixels.shape[-3:] != pixels.shape[-3:]:
            raise ValueError(
                f"goal image {tuple(goal_pixels.shape[-3:])} and current image "
                f"{tuple(pixels.shape[-3:])} must have the same [H, W, 3]; resize the goal image."
            )
        self.model.eval()
        feat = self.model.encode(pixels.to(self.device))
        goal = self.model.encode(goal_pixels.to(self.device)).expand_as(feat)
        return TensorDict(
            {IMAGE_FEAT: feat, GOAL_IMAGE_FEAT: goal},
            batch_size=feat.shape[:-1],
            device=self.device,
        )


def make_baseline_env(model: nn.Module) -> ObjectModelEnv | FeatureModelEnv:
    """The model env of a baseline: :class:`ObjectModelEnv` (IN/VisIN) or :class:`FeatureModelEnv`."""
    if isinstance(model, ObjectInteractionModel):
        return ObjectModelEnv(model)
    if isinstance(model, ImageForwardModel):
        return FeatureModelEnv(model)
    raise TypeError(
        f"No baseline model env for {type(model).__name__}; model_mpc plans with IN, VisIN, Forw "
        "or ForwInv (use the kinet_graph / kinet_keypoints methods for KINet)."
    )


class BaselineMPCController:
    """MPC on the distance to the goal with a baseline model (``Controller`` protocol).

    IN/VisIN plan on the true object positions towards the true goal positions; Forw/ForwInv
    plan on image features towards the goal image's feature.

    Args:
        model: A baseline model (see :func:`make_baseline_env`).
        planner: :class:`GraphMPCPlanner` settings.
        seed: Seed of the planner's sampling.
    """

    def __init__(self, model: nn.Module, planner: Mapping[str, Any], seed: int) -> None:
        self.env = make_baseline_env(model)
        self.planner = GraphMPCPlanner(
            self.env, generator=torch.Generator().manual_seed(seed), **dict(planner)
        )
        self.episode: Episode | None = None

    def reset(self, episode: Episode) -> None:
        """Keeps the episode's goal and clears the warm start."""
        self.episode = episode
        self.planner.reset()

    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        """Plans from the current observation (``pixels``, ``object_pos``)."""
        if self.episode is None:
            raise RuntimeError(
                "BaselineMPCController.act called before reset(episode); reset it first."
            )
        pixels = torch.from_numpy(np.array(observation["pixels"]))
        if isinstance(self.env, ObjectModelEnv):
            pos = torch.as_tensor(observation["object_pos"], dtype=torch.float32)
            goal = torch.as_tensor(self.episode.goal_pos, dtype=torch.float32)
            state = self.env.observe(pixels, pos, goal)
        else:
            state = self.env.observe(pixels, torch.from_numpy(np.array(self.episode.goal_pixels)))
        return self.planner(state).get(ACTION).cpu().numpy()
