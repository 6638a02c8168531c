"""Rearrangement by MPC: settings, episodes with reachable goals, controllers, the method
registry, a parallel runner that returns results, and the report written from them.

Dependency order inside the package: ``settings`` <- ``results`` <- ``episodes`` <-
``controllers`` <- ``methods`` <- ``runner``; ``report`` depends on ``settings`` and ``results``.
"""

from __future__ import annotations

from kinet_rl.rearrangement.controllers import PlannerController, RandomController
from kinet_rl.rearrangement.episodes import (
    Controller,
    Episode,
    make_episode,
    run_episode,
    run_episodes,
)
from kinet_rl.rearrangement.methods import METHODS, Method, MethodContext
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
    "Controller",
    "Episode",
    "EpisodeResult",
    "Method",
    "MethodContext",
    "PlannerController",
    "RandomController",
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
