"""What a rearrangement evaluation measured: episode outcomes and their summaries."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kinet_rl.rearrangement.settings import Condition, RearrangementSettings
from kinet_rl.stats import t_975, wilson_interval

#: ``{condition name: {method: stats}}`` as in ``rearrangement.json``.
Summary = dict[str, dict[str, dict[str, Any]]]


@dataclass
class EpisodeResult:
    """Ground-truth outcome of one controller on one episode."""

    method: str
    seed: int
    distances: np.ndarray  # [T + 1] mean object distance to goal, metres
    success: bool
    unstable: bool
    frames: list[np.ndarray] = field(default_factory=list)  # [H, W, 3] per step (if recorded)
    keypoints: list[np.ndarray] = field(default_factory=list)  # [K, 2] in [-1, 1] per step
    goal_pixels: np.ndarray | None = None
    goal_keypoints: np.ndarray | None = None


def summarize(episodes: list[EpisodeResult]) -> dict[str, Any]:
    """Mean, standard error and 95% interval of the distance curve and final distance; success rate.

    The distance interval is Student's t over episodes (zero for one episode); the success
    interval is Wilson's.
    """
    curves = np.stack([r.distances for r in episodes])  # [E, T + 1]
    n = len(episodes)
    sem = curves.std(0, ddof=1) / np.sqrt(n) if n > 1 else np.zeros(curves.shape[1])
    half = sem * (t_975(n - 1) if n > 1 else 0.0)
    successes = sum(r.success for r in episodes)
    return {
        "episodes": n,
        "mean_curve": curves.mean(0).tolist(),
        "sem_curve": sem.tolist(),
        "ci95_curve": half.tolist(),
        "initial_distance": float(curves[:, 0].mean()),
        "final_distance": float(curves[:, -1].mean()),
        "final_distance_sem": float(sem[-1]),
        "final_distance_ci95": float(half[-1]),
        "success_rate": successes / n,
        "success_ci95": list(wilson_interval(successes, n)),
        "unstable": int(sum(r.unstable for r in episodes)),
    }


@dataclass
class RearrangementResults:
    """Episodes of every method on every condition, in the order they were asked for.

    Attributes:
        settings: The evaluation's settings.
        episodes: ``{condition: {method: [episode results by seed]}}``.
        labels: Display label of each method.
    """

    settings: RearrangementSettings
    episodes: dict[Condition, dict[str, list[EpisodeResult]]]
    labels: dict[str, str]

    def conditions(self, role: str) -> list[Condition]:
        """The conditions of one role (``"comparison"``, ``"generalization"``, ``"background"``)."""
        return [c for c in self.episodes if c.role == role]

    def stats(self, condition: Condition) -> dict[str, dict[str, Any]]:
        """:func:`summarize` of each method on ``condition``."""
        return {method: summarize(eps) for method, eps in self.episodes[condition].items()}

    def summary(self) -> Summary:
        """Statistics by condition name and method (the JSON form)."""
        return {condition.name: self.stats(condition) for condition in self.episodes}
