"""Goal-conditioned control with a trained KINet: model env, push planning, rearrangement.

Unlike :mod:`kinet_rl.planners` (generic), this package depends on :mod:`kinet_rl.models`.
"""

from __future__ import annotations

from kinet_rl.control.evaluation import RearrangementSettings, evaluate_rearrangement
from kinet_rl.control.model_env import KINetModelEnv, chamfer_distance, make_kinet_planner
from kinet_rl.control.oracle import AnalyticPushModelEnv, analytic_push
from kinet_rl.control.robot import Push, PushPlanner

__all__ = [
    "AnalyticPushModelEnv",
    "KINetModelEnv",
    "Push",
    "PushPlanner",
    "RearrangementSettings",
    "analytic_push",
    "chamfer_distance",
    "evaluate_rearrangement",
    "make_kinet_planner",
]
