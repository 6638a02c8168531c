"""Rearrangement by MPC: settings, episodes with reachable goals, policies, the method
registry, a parallel runner that returns results, and the report written from them.

Dependency order inside the package: ``settings`` <- ``results`` <- ``episodes`` <-
``policies`` <- ``methods`` <- ``runner``; ``report`` depends on ``settings`` and ``results``.
"""

from __future__ import annotations

from kinet_rl.rearrangement.episodes import (
    Episode,
    EpisodesEnv,
    Policy,
    make_episode,
    run_episode,
    run_episodes,
)
from kinet_rl.rearrangement.methods import METHODS, Method, MethodContext
from kinet_rl.rearrangement.policies import PlannerPolicy, RandomPolicy
from kinet_rl.rearrangement.report import write_report
from kinet_rl.rearrangement.results import EpisodeResult, RearrangementResults, summarize
from kinet_rl.rearrangement.runner import run_rearrangement
from kinet_rl.rearrangement.settings import (
    Condition,
    RearrangementSettings,
    TaskSettings,
    generalization_key,
)

__all__ = [
    "METHODS",
    "Condition",
    "Episode",
    "EpisodesEnv",
    "EpisodeResult",
    "Method",
    "MethodContext",
    "PlannerPolicy",
    "Policy",
    "RandomPolicy",
    "RearrangementResults",
    "RearrangementSettings",
    "TaskSettings",
    "generalization_key",
    "make_episode",
    "run_episode",
    "run_episodes",
    "run_rearrangement",
    "summarize",
    "write_report",
]
