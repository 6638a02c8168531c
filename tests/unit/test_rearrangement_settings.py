"""Tests for the rearrangement settings, conditions, summaries and report text (no simulation)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from omegaconf import OmegaConf

from kinet_rl.control.evaluation import RearrangementSettings, make_jobs, summarize
from kinet_rl.control.rearrange import METHODS, EpisodeResult, all_within, mean_goal_distance
from kinet_rl.control.report import VIDEO_SCALE, markdown, video_frames

CONF = Path(__file__).resolve().parents[2] / "conf"


def yaml_settings(**eval_overrides) -> RearrangementSettings:
    eval_cfg = OmegaConf.to_container(OmegaConf.load(CONF / "eval" / "rearrange.yaml"))
    env_cfg = OmegaConf.to_container(OmegaConf.load(CONF / "env" / "blocks.yaml"))
    return RearrangementSettings.from_dicts({**eval_cfg, **eval_overrides}, env_cfg)


def test_yaml_settings_build_the_comparison_and_table_ii_conditions() -> None:
    settings = yaml_settings()
    assert settings.task.num_steps == 40 and settings.scene.num_objects == 3
    conditions = settings.conditions()
    assert conditions[0].name == "comparison"
    assert set(conditions[0].methods) == set(METHODS)
    names = {c.name for c in conditions}
    assert {f"n{n}_geom_{g}" for n in range(1, 6) for g in ("train", "gen")} <= names
    assert "background_random" in names
    assert [c.name for c in settings.conditions(generalization=False)] == ["comparison"]


def test_jobs_share_seeds_across_methods_and_record_videos() -> None:
    settings = yaml_settings(episodes=3, videos=1)
    jobs = make_jobs(settings, settings.conditions(generalization=False))
    assert len(jobs) == 3 * len(settings.methods)
    seeds = {m: [j.seed for j in jobs if j.method == m] for m in settings.methods}
    assert all(s == seeds["random"] for s in seeds.values())
    assert [(j.method, j.seed) for j in jobs if j.record] == [
        (settings.kinet_method, settings.seed)
    ]


def test_bad_settings_are_reported() -> None:
    with pytest.raises(ValueError, match="Unknown rearrangement settings"):
        yaml_settings(episodez=3)
    with pytest.raises(ValueError, match="Unknown methods"):
        yaml_settings(methods=["kinet_graph", "teleport"])
    with pytest.raises(ValueError, match="kinet_method"):
        yaml_settings(kinet_method="kinet_keypoints")


def test_distance_success_and_summary() -> None:
    pos = np.array([[0.0, 0.0], [0.1, 0.0]])
    goal = np.array([[0.0, 0.03], [0.1, 0.01]])
    assert mean_goal_distance(pos, goal) == pytest.approx(0.02)
    assert all_within(pos, goal, 0.03) and not all_within(pos, goal, 0.02)
    results = [
        EpisodeResult("random", s, np.array([0.1, d]), d < 0.03, False)
        for s, d in ((0, 0.02), (1, 0.04))
    ]
    stats = summarize(results)
    assert stats["final_distance"] == pytest.approx(0.03)
    assert stats["final_distance_sem"] == pytest.approx(np.std([0.02, 0.04], ddof=1) / np.sqrt(2))
    assert stats["success_rate"] == 0.5 and stats["mean_curve"][0] == pytest.approx(0.1)


def test_markdown_lists_methods_and_the_generalization_table() -> None:
    settings = yaml_settings(num_objects=[1, 2], geometries=["train"], backgrounds=[])
    stats = summarize([EpisodeResult("x", 0, np.array([0.08, 0.012]), True, False)])
    summary = {
        "comparison": {"kinet_graph": stats, "random": stats},
        "n1_geom_train": {settings.kinet_method: stats},
    }
    text = markdown(settings, summary, "plot.png")
    assert "| KINet-GraphMPC (paper S) | 1 | 80.0 | 12.0 ± 0.0 | 100% |" in text
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
