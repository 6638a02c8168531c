"""Tests for the ground-truth metrics of an episode and the summaries of results (no simulation)."""

from __future__ import annotations

import numpy as np
import pytest

from kinet_rl.rearrangement.episodes import all_within, mean_goal_distance
from kinet_rl.rearrangement.results import EpisodeResult, RearrangementResults, summarize
from kinet_rl.rearrangement.settings import RearrangementSettings


def test_distance_and_success() -> None:
    pos = np.array([[0.0, 0.0], [0.1, 0.0]])
    goal = np.array([[0.0, 0.03], [0.1, 0.01]])
    assert mean_goal_distance(pos, goal) == pytest.approx(0.02)
    assert all_within(pos, goal, 0.03) and not all_within(pos, goal, 0.02)


def test_summary_statistics() -> None:
    results = [
        EpisodeResult("random", s, np.array([0.1, d]), d < 0.03, False)
        for s, d in ((0, 0.02), (1, 0.04))
    ]
    stats = summarize(results)
    assert stats["final_distance"] == pytest.approx(0.03)
    assert stats["final_distance_sem"] == pytest.approx(np.std([0.02, 0.04], ddof=1) / np.sqrt(2))
    assert stats["success_rate"] == 0.5 and stats["mean_curve"][0] == pytest.approx(0.1)
    # 95% intervals: Student's t with 1 dof over episodes; Wilson for the success rate.
    assert stats["final_distance_ci95"] == pytest.approx(12.706 * stats["final_distance_sem"])
    assert stats["ci95_curve"][0] == 0.0  # every episode starts at 0.1
    low, high = stats["success_ci95"]
    assert 0.0 < low < 0.5 < high < 1.0


def test_results_summarize_each_condition_by_name() -> None:
    settings = RearrangementSettings(methods=("random",), num_objects=(2,), geometries=("train",))
    comparison, cell = settings.conditions()
    episode = EpisodeResult("random", 0, np.array([0.1, 0.05]), False, False)
    results = RearrangementResults(
        settings, {comparison: {"random": [episode]}, cell: {"random": [episode, episode]}}, {}
    )
    assert results.conditions("generalization") == [cell] and not results.conditions("background")
    assert results.stats(cell)["random"] == summarize([episode, episode])
    assert results.summary() == {
        "comparison": {"random": summarize([episode])},
        "n2_geom_train": {"random": summarize([episode, episode])},
    }


def test_summary_reports_the_goal_ssim_and_how_it_tracks_the_distance() -> None:
    distances = (np.array([0.10, 0.06, 0.02]), np.array([0.08, 0.09, 0.05]))
    similarities = (np.array([0.70, 0.80, 0.95]), np.array([0.75, 0.72, 0.85]))
    episodes = [
        EpisodeResult("oracle", s, d, False, False, goal_ssim=g)
        for s, (d, g) in enumerate(zip(distances, similarities, strict=True))
    ]
    stats = summarize(episodes)
    assert stats["final_goal_ssim"] == pytest.approx(0.9)
    assert stats["goal_ssim_curve"] == pytest.approx([0.725, 0.76, 0.9])
    # Pooled over both episodes' pushes the SSIM falls exactly as the distance rises.
    assert stats["goal_ssim_spearman"] == pytest.approx(-1.0)
    unmeasured = summarize([EpisodeResult("random", 0, distances[0], False, False)])
    assert unmeasured["final_goal_ssim"] is None and unmeasured["goal_ssim_spearman"] is None
