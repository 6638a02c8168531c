"""Planners over any TorchRL model env: GraphMPC (CEM, MPPI), goal rewards, a model-env base.

Imports neither ``kinet_rl.models`` nor hydra, so any TorchRL pipeline can use it with its own
world model.
"""

from __future__ import annotations

from kinet_rl.planners.costs import GoalReward, graph_similarity_reward, keypoint_goal_reward
from kinet_rl.planners.graph_mpc import GraphMPCPlanner
from kinet_rl.planners.model_env import StateModelEnv

__all__ = [
    "GoalReward",
    "GraphMPCPlanner",
    "StateModelEnv",
    "graph_similarity_reward",
    "keypoint_goal_reward",
]
