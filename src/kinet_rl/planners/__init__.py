"""Planning over any world model of pushes: the world-model interface and its TorchRL
``WorldModelEnv``, the goal objectives, GraphMPC (CEM, MPPI).

Imports neither ``kinet_rl.models`` nor hydra, so any TorchRL pipeline can use it with its own
world model.
"""

from __future__ import annotations

from kinet_rl.planners.graph_mpc import GraphMPCPlanner
from kinet_rl.planners.objectives import (
    OBJECTIVES,
    GoalObjective,
    chamfer_distance,
    goal_objective,
    goal_reward_head,
)
from kinet_rl.planners.world_model import (
    VALIDATED_PLANNER,
    ModelCapabilities,
    PlanningDefaults,
    PlanningInterface,
    PushWorldModel,
    PushWorldModelEnv,
    push_dynamics,
)

__all__ = [
    "OBJECTIVES",
    "VALIDATED_PLANNER",
    "GoalObjective",
    "GraphMPCPlanner",
    "ModelCapabilities",
    "PlanningDefaults",
    "PlanningInterface",
    "PushWorldModel",
    "PushWorldModelEnv",
    "chamfer_distance",
    "goal_objective",
    "goal_reward_head",
    "push_dynamics",
]
