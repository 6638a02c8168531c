"""Planning objectives: every goal cost of the project in one registry, and the reward head.

A :class:`GoalObjective` scores a predicted state entry against its goal entry (both in the
tensordict), larger is closer. :func:`goal_reward_head` wraps one into the reward head of a
``torchrl.modules.WorldModel``: it reads ``("next", state_key)`` and ``goal_key`` and writes
``("next", "reward")`` ``[*B, 1]``. Models declare which objectives they can plan with
(:class:`~kinet_rl.planners.world_model.PlanningInterface`); nothing else computes a goal cost.

Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 3.4 (GraphMPC's ``S``) and Sec. 5 ("for all
baseline models, we perform MPC directly on the distance to the goal").
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from tensordict import NestedKey
from tensordict.nn import TensorDictModule
from torch import Tensor, nn

from kinet_rl.keys import (
    GOAL_IMAGE_FEAT,
    GOAL_KP_NODE_EMB,
    GOAL_KP_POS,
    GOAL_OBJECT_POS,
    IMAGE_FEAT,
    KP_NODE_EMB,
    KP_POS,
    KP_POS_EMB,
    OBJECT_POS,
    REWARD,
)


def chamfer_distance(pos: Tensor, goal_pos: Tensor) -> Tensor:
    """Symmetric Chamfer distance ``[*B]`` between point sets ``[*B, K, 2]`` and ``[*B, M, 2]``.

    The mean over points of the distance to the nearest point of the other set, averaged over
    both directions; it needs no correspondence between the sets.
    """
    dist = torch.cdist(pos, goal_pos.expand(*pos.shape[:-2], *goal_pos.shape[-2:]))  # [*B, K, M]
    return 0.5 * (dist.min(-1).values.mean(-1) + dist.min(-2).values.mean(-1))


def _squared_distance(state: Tensor, goal: Tensor) -> Tensor:
    return -(state - goal).pow(2).sum(-1).mean(-1)


def _distance(state: Tensor, goal: Tensor) -> Tensor:
    return -(state - goal).norm(dim=-1).mean(-1)


def _cosine(state: Tensor, goal: Tensor) -> Tensor:
    return F.cosine_similarity(state.flatten(-2), goal.flatten(-2), dim=-1)


def _dot(state: Tensor, goal: Tensor) -> Tensor:
    return (state * goal).sum(dim=(-2, -1)) / goal.shape[-2]


def _chamfer(state: Tensor, goal: Tensor) -> Tensor:
    return -chamfer_distance(state, goal)


def _feature_distance(state: Tensor, goal: Tensor) -> Tensor:
    return -(state - goal).pow(2).sum(-1)


@dataclass(frozen=True)
class GoalObjective:
    """A goal cost: ``score(state, goal) -> [*B]``, larger is closer to the goal.

    Attributes:
        name: Its key in :data:`OBJECTIVES`, configs, checkpoints and ``--objective``.
        label: How reports name it.
        state_key: The predicted state entry it scores (the dynamics writes it under ``"next"``).
        goal_key: The goal entry it compares with (the encoder writes it).
        score: ``(state [*B, ...], goal [*B, ...]) -> [*B]``.
    """

    name: str
    label: str
    state_key: NestedKey
    goal_key: NestedKey
    score: Callable[[Tensor, Tensor], Tensor]


#: Every planning objective, by name.
OBJECTIVES: dict[str, GoalObjective] = {
    objective.name: objective
    for objective in (
        GoalObjective(
            "graph",
            "paper S, cosine: cosine of predicted next graph and goal graph",
            KP_NODE_EMB,
            GOAL_KP_NODE_EMB,
            _cosine,
        ),
        GoalObjective(
            "graph_dot",
            "paper S, dot product: (1/K) sum_k n_k . n_goal_k",
            KP_NODE_EMB,
            GOAL_KP_NODE_EMB,
            _dot,
        ),
        GoalObjective(
            "graph_distance",
            "node-embedding distance: -(1/K) sum_k |n(x_k, phi_k) - n_goal_k|^2",
            KP_POS_EMB,
            GOAL_KP_NODE_EMB,
            _squared_distance,
        ),
        GoalObjective("keypoints", "keypoint Chamfer distance", KP_POS, GOAL_KP_POS, _chamfer),
        GoalObjective(
            "keypoints_l2",
            "index-matched keypoint L2: -(1/K) sum_k |x_k - g_k|^2",
            KP_POS,
            GOAL_KP_POS,
            _squared_distance,
        ),
        GoalObjective(
            "keypoints_distance",
            "index-matched keypoint distance: -(1/K) sum_k |x_k - g_k|",
            KP_POS,
            GOAL_KP_POS,
            _distance,
        ),
        GoalObjective(
            "object_distance",
            "ground-truth object distance (metres): -(1/N) sum_n |p_n - g_n|",
            OBJECT_POS,
            GOAL_OBJECT_POS,
            _distance,
        ),
        GoalObjective(
            "feature_distance",
            "whole-image feature distance: -|z - z_goal|^2",
            IMAGE_FEAT,
            GOAL_IMAGE_FEAT,
            _feature_distance,
        ),
    )
}


def goal_objective(objective: str | GoalObjective) -> GoalObjective:
    """The objective named ``objective`` (an objective is returned as it is)."""
    if isinstance(objective, GoalObjective):
        return objective
    if objective not in OBJECTIVES:
        raise ValueError(
            f"Unknown planning objective {objective!r}; choose from {list(OBJECTIVES)}."
        )
    return OBJECTIVES[objective]


class _Score(nn.Module):
    def __init__(self, score: Callable[[Tensor, Tensor], Tensor]) -> None:
        super().__init__()
        self.score = score

    def forward(self, state: Tensor, goal: Tensor) -> Tensor:
        return self.score(state, goal).unsqueeze(-1)


def goal_reward_head(objective: str | GoalObjective) -> TensorDictModule:
    """The reward head of a world model planning with ``objective``: ``("next", "reward")``
    ``[*B, 1]`` from ``("next", state_key)`` and ``goal_key``."""
    objective = goal_objective(objective)
    state_key = (
        objective.state_key if isinstance(objective.state_key, tuple) else (objective.state_key,)
    )
    return TensorDictModule(
        _Score(objective.score),
        in_keys=[("next", *state_key), objective.goal_key],
        out_keys=[REWARD],
    )
