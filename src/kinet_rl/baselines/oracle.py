"""Oracle model env: an analytic push model on the simulator's ground-truth object positions."""

from __future__ import annotations

import torch
from tensordict.nn import TensorDictModule
from torch import Tensor, nn

from kinet_rl.keys import ACTION, GOAL_OBJECT_POS, OBJECT_POS, STEP_REWARD
from kinet_rl.planners.model_env import StateModelEnv


def analytic_push(
    object_pos: Tensor, action: Tensor, half_size: float, contact_radius: float
) -> Tensor:
    """Moves discs hit by a straight push so that they end just ahead of the push's end.

    Each object is a disc of radius ``contact_radius`` (object plus pusher). With push start
    ``s``, unit direction ``d`` and length ``L``, an object at along-track coordinate ``t`` and
    lateral offset ``l`` is hit when ``l < R`` and ``t`` lies in ``(0, L + R)``; it slides along
    ``d`` to ``t' = L + sqrt(R^2 - l^2)`` (touching the pusher's final position). Objects do not
    push each other and do not rotate.

    Args:
        object_pos: ``[*B, N, 2]`` metres.
        action: ``[*B, 4]`` push (start x, y, end x, y) in ``[-1, 1]``.
        half_size: Workspace half size, metres (maps the action to metres).
        contact_radius: ``R``, metres.

    Returns:
        ``[*B, N, 2]`` object positions after the push.
    """
    ends = action.clamp(-1.0, 1.0).reshape(*action.shape[:-1], 1, 2, 2) * half_size
    start, end = ends[..., 0, :], ends[..., 1, :]  # [*B, 1, 2]
    delta = end - start
    length = delta.norm(dim=-1, keepdim=True).clamp_min(1e-6)  # [*B, 1, 1]
    direction = delta / length
    rel = object_pos - start  # [*B, N, 2]
    along = (rel * direction).sum(-1, keepdim=True)  # [*B, N, 1]
    lateral = (rel - along * direction).norm(dim=-1, keepdim=True)
    hit = (lateral < contact_radius) & (along > 0) & (along < length + contact_radius)
    final_along = length + (contact_radius**2 - lateral.clamp_max(contact_radius) ** 2).sqrt()
    shift = torch.where(hit, (final_along - along).clamp_min(0.0), torch.zeros_like(along))
    return object_pos + shift * direction


class _AnalyticStep(nn.Module):
    def __init__(self, half_size: float, contact_radius: float) -> None:
        super().__init__()
        self.half_size = half_size
        self.contact_radius = contact_radius

    def forward(self, pos: Tensor, action: Tensor, goal: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        nxt = analytic_push(pos, action, self.half_size, self.contact_radius)
        reward = -(nxt - goal).norm(dim=-1).mean(-1, keepdim=True)  # [*B, 1] mean metres
        return nxt, reward, goal


class AnalyticPushModelEnv(StateModelEnv):
    """A model env on ground-truth object positions with :func:`analytic_push` dynamics.

    Used for the oracle baseline: it plans with the true object state and a hand-written push
    model, so it bounds what a planner gains from a perfect state estimate (its dynamics are
    approximate: no rotation, no object-object contact). Reward: minus the mean distance
    (metres) of the objects to their goal positions (identities known).

    Keys:
        State/observation: ``OBJECT_POS`` ``[*B, N, 2]`` and ``GOAL_OBJECT_POS`` ``[*B, N, 2]``.
        Action ``[*B, 4]`` in ``[-1, 1]``; reward ``[*B, 1]``.

    Args:
        num_objects: ``N``.
        half_size: Workspace half size, metres.
        contact_radius: Object-plus-pusher radius of the push model, metres.
    """

    def __init__(self, num_objects: int, half_size: float, contact_radius: float = 0.035) -> None:
        step = TensorDictModule(
            _AnalyticStep(half_size, contact_radius),
            in_keys=[OBJECT_POS, ACTION, GOAL_OBJECT_POS],
            out_keys=[OBJECT_POS, STEP_REWARD, GOAL_OBJECT_POS],
        )
        super().__init__(
            step,
            {OBJECT_POS: (num_objects, 2), GOAL_OBJECT_POS: (num_objects, 2)},
            reset_hint="pass the start and goal object positions, metres.",
        )
