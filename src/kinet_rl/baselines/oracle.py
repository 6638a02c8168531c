"""The oracle: an analytic push model on the simulator's ground-truth object positions."""

from __future__ import annotations

import torch
from tensordict.nn import TensorDictModule
from torch import Tensor, nn

from kinet_rl.keys import ACTION, GOAL_OBJECT_POS, OBJECT_POS
from kinet_rl.planners.objectives import goal_reward_head
from kinet_rl.planners.world_model import (
    ModelCapabilities,
    PlanningDefaults,
    PushWorldModel,
    check_objective,
    push_dynamics,
)


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


class AnalyticPushModel(nn.Module):
    """The oracle's world model: ground-truth object positions and :func:`analytic_push`.

    It plans with the true object state and a hand-written push model, so it bounds what a
    planner gains from a perfect state estimate (its dynamics are approximate: no rotation, no
    object-object contact). Objective: the mean distance (metres) of the objects to their goal
    positions (identities known).

    Keys:
        Encoder: ``OBJECT_POS`` ``[*B, N, 2]`` and ``GOAL_OBJECT_POS`` ``[*B, N, 2]`` in, both
        carried as the state. Action ``[*B, 4]`` in ``[-1, 1]``; reward ``[*B, 1]``.

    Args:
        num_objects: ``N``.
        half_size: Workspace half size, metres.
        contact_radius: Object-plus-pusher radius of the push model, metres.
        planning: Planning defaults (objective ``object_distance``).
    """

    capabilities = ModelCapabilities(
        observes=(OBJECT_POS,), goal=(GOAL_OBJECT_POS,), objectives=("object_distance",)
    )
    label = "Oracle"
    scene = None

    def __init__(
        self,
        num_objects: int,
        half_size: float,
        contact_radius: float = 0.035,
        planning: PlanningDefaults | None = None,
    ) -> None:
        super().__init__()
        self.num_objects = num_objects
        self.half_size = half_size
        self.contact_radius = contact_radius
        self.planning = planning or PlanningDefaults("object_distance")

    def forward(self, pos: Tensor, action: Tensor) -> tuple[Tensor]:
        """Object positions after ``action``."""
        return (analytic_push(pos, action, self.half_size, self.contact_radius),)

    def world_model(self, objective: str | None = None) -> PushWorldModel:
        """Its ``torchrl.modules.WorldModel`` (see the class ``Keys:``)."""
        objective = check_objective(
            self.capabilities, objective or self.planning.objective, self.label
        )
        n = self.num_objects
        return PushWorldModel(
            TensorDictModule(nn.Identity(), in_keys=[OBJECT_POS], out_keys=[OBJECT_POS]),
            push_dynamics(self, [OBJECT_POS, ACTION], [OBJECT_POS], [GOAL_OBJECT_POS]),
            goal_reward_head(objective),
            {OBJECT_POS: (n, 2), GOAL_OBJECT_POS: (n, 2)},
        )
