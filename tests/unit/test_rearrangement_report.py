"""Tests for the rearrangement report's markdown and videos (no simulation)."""

from __future__ import annotations

import numpy as np

from kinet_rl.rearrangement.methods import METHODS
from kinet_rl.rearrangement.report import VIDEO_SCALE, markdown, video_frames
from kinet_rl.rearrangement.results import EpisodeResult, RearrangementResults
from kinet_rl.rearrangement.settings import RearrangementSettings


def test_markdown_lists_methods_and_the_generalization_table() -> None:
    settings = RearrangementSettings(num_objects=(1, 2), geometries=("train",), backgrounds=())
    comparison, n1, _ = settings.conditions()  # the n2 cell has no results: shown as "-"
    episode = EpisodeResult("x", 0, np.array([0.08, 0.012]), True, False)
    measured = EpisodeResult("x", 0, np.array([0.08, 0.012]), True, False, np.array([0.6, 0.9]))
    episodes = {
        comparison: {"kinet_graph": [episode], "random": [measured]},
        n1: {settings.kinet_method: [episode]},
    }
    labels = {name: METHODS[name].label for name in ("kinet_graph", "random")}
    text = markdown(RearrangementResults(settings, episodes, labels), "plot.png")
    # One success in one episode: 100% with the Wilson interval [21, 100].
    assert (
        "| KINet-GraphMPC (paper S, cosine) | 1 | 80.0 | 12.0 ± 0.0 | 100% [21, 100] | - | - |"
        in text
    )  # an episode without SSIM (e.g. stored by an older version) shows "-"
    assert "| 1 | 80.0 | 12.0 ± 0.0 | 100% [21, 100] | 0.900 | -1.000 |" in text
    assert "rho: Spearman's rank correlation of the SSIM with the distance" in text
    assert "Test episodes, seeds 50000 + i" in text
    assert "Planner of every method: 64 candidates x 3 iterations (top 8), horizon 1" in text
    assert "| 1 | 12.0 ± 0.0 (80.0) |" in text and "| 2 | - |" in text
    assert "![distance to goal](plot.png)" in text


def test_video_frames_put_each_step_beside_the_goal() -> None:
    frames = [np.full((8, 8, 3), v, np.uint8) for v in (0, 50, 100)]
    result = EpisodeResult(
        "kinet_graph",
        0,
        np.zeros(3),
        False,
        False,
        frames=frames,
        keypoints=[np.zeros((2, 2))] * 2,
        goal_pixels=np.full((8, 8, 3), 255, np.uint8),
        goal_keypoints=np.zeros((2, 2)),
    )
    video = video_frames(result)
    size = 8 * VIDEO_SCALE
    assert len(video) == 3 and video[0].shape == (size + 4, 2 * size + 6, 3)
    assert (video[2][2 : 2 + size, 2 : 2 + size] == 100).all()  # last frame: no keypoints drawn
    assert (video[0][size // 2, 2 + size + 2 :] != 255).any()  # goal has a keypoint at its centre
