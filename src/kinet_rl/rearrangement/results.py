"""What a rearrangement evaluation measured: episode outcomes and their summaries."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kinet_rl.rearrangement.settings import Condition, RearrangementSettings
from kinet_rl.stats import spearman, t_975, wilson_interval

#: ``{condition name: {method: stats}}`` as in ``rearrangement.json``.
Summary = dict[str, dict[str, dict[str, Any]]]


@dataclass
class EpisodeResult:
    """Outcome of one policy on one episode: ground truth, and the goal-image SSIM."""

    method: str
    seed: int
    distances: np.ndarray  # [T + 1] mean object distance to goal, metres
    success: bool
    unstable: bool
    goal_ssim: np.ndarray | None = None  # [T + 1] SSIM of the camera image to the goal image
    frames: list[np.ndarray] = field(default_factory=list)  # [H, W, 3] per step (if recorded)
    keypoints: list[np.ndarray] = field(default_factory=list)  # [K, 2] in [-1, 1] per step
    goal_pixels: np.ndarray | None = None
    goal_keypoints: np.ndarray | None = None


def summarize(episodes: list[EpisodeResult]) -> dict[str, Any]:
    """Mean, standard error and 95% interval of the distance curve and final distance; success
    rate; the goal-image SSIM and how it tracks the distance.

    The distance interval is Student's t over episodes (zero for one episode); the success
    interval is Wilson's. ``goal_ssim_spearman`` is Spearman's rank correlation between the
    SSIM and the ground-truth distance over every step of every episode (near -1: the SSIM
    rises as the objects near their goals). The SSIM entries are None when an episode did not
    measure it, the correlation also when it is undefined (e.g. nothing moved).
    """
    curves = np.stack([r.distances for r in episodes])  # [E, T + 1]
    n = len(episodes)
    sem = curves.std(0, ddof=1) / np.sqrt(n) if n > 1 else np.zeros(curves.shape[1])
    half = sem * (t_975(n - 1) if n > 1 else 0.0)
    successes = sum(r.success for r in episodes)
    ssim = None
    if all(r.goal_ssim is not None for r in episodes):
        ssim = np.stack([r.goal_ssim for r in episodes])  # type: ignore[misc]  # [E, T + 1]
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
        "goal_ssim_curve": None if ssim is None else ssim.mean(0).tolist(),
        "final_goal_ssim": None if ssim is None else float(ssim[:, -1].mean()),
        "goal_ssim_spearman": None if ssim is None else spearman(ssim.ravel(), curves.ravel()),
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
