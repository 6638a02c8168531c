"""Rearrangement in the MuJoCo simulator: episodes, oracle vs random, report and CLIs (slow)."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from PIL import Image

from kinet_rl import plan
from kinet_rl.envs import SceneSettings
from kinet_rl.evaluate import evaluate
from kinet_rl.models.checkpointing import checkpoint_scene
from kinet_rl.pipeline import evaluate_rearrangement
from kinet_rl.rearrangement import runner
from kinet_rl.rearrangement.episodes import make_episode, mean_goal_distance, run_episode
from kinet_rl.rearrangement.methods import METHODS, MethodContext
from kinet_rl.rearrangement.policies import RandomPolicy
from kinet_rl.rearrangement.settings import RearrangementSettings, TaskSettings

pytestmark = pytest.mark.slow

SCENE = SceneSettings(image_size=32)
ORACLE = {"planning_horizon": 1, "optim_steps": 5, "num_candidates": 256, "top_k": 16}


def test_episode_goal_is_reproducible_reachable_and_start_restored() -> None:
    task = TaskSettings(goal_pushes=3, min_goal_distance=0.02)
    first, second = make_episode(SCENE, task, 5), make_episode(SCENE, task, 5)
    try:
        np.testing.assert_array_equal(first.goal_pos, second.goal_pos)
        np.testing.assert_array_equal(first.goal_pixels, second.goal_pixels)
        assert mean_goal_distance(first.start["object_pos"], first.goal_pos) >= 0.02
        pos, _ = first.env.task.object_poses(first.env.physics)  # physics is back at the start
        np.testing.assert_allclose(pos, first.start["object_pos"], atol=1e-6)
    finally:
        first.close()
        second.close()


def test_oracle_mpc_beats_random_pushes_in_the_simulator() -> None:
    task = TaskSettings(num_steps=10)
    finals: dict[str, list[float]] = {"oracle": [], "random": []}
    final_ssim: dict[str, list[float]] = {"oracle": [], "random": []}
    initial = []
    for seed in range(3):
        for method in finals:
            episode = make_episode(SCENE, task, seed)
            oracle = RearrangementSettings(scene=SCENE, planner=ORACLE, oracle_contact_radius=0.035)
            policy = (
                METHODS["oracle"].policy(MethodContext(None, SCENE, oracle, (seed,)))
                if method == "oracle"
                else RandomPolicy([seed])
            )
            result = run_episode(episode, policy, method, task)
            episode.close()
            finals[method].append(result.distances[-1])
            final_ssim[method].append(result.goal_ssim[-1])
            assert result.goal_ssim.shape == result.distances.shape == (task.num_steps + 1,)
        initial.append(result.distances[0])
    assert np.mean(finals["oracle"]) < 0.5 * np.mean(initial)
    assert np.mean(finals["oracle"]) < 0.5 * np.mean(finals["random"])
    # The image metric agrees: the oracle's last images look more like the goal's.
    assert np.mean(final_ssim["oracle"]) > np.mean(final_ssim["random"])


def test_evaluate_rearrangement_writes_plot_markdown_json_and_video_and_resumes(
    tmp_path: Path, tiny_kinet, monkeypatch
) -> None:
    settings = RearrangementSettings(
        scene=SCENE,
        task=TaskSettings(num_steps=3),
        episodes=2,
        workers=2,
        planner={"planning_horizon": 1, "optim_steps": 2, "num_candidates": 16, "top_k": 4},
        num_objects=(2,),
        geometries=("gen",),
        backgrounds=("random",),
        generalization_episodes=1,
    )
    out = evaluate_rearrangement(tiny_kinet(), settings, tmp_path, generalization=True)
    summary = out["summary"]
    assert set(summary) == {"comparison", "n2_geom_gen", "background_random"}
    assert set(summary["comparison"]) == set(settings.methods)
    for stats in summary["comparison"].values():
        assert stats["episodes"] == 2 and len(stats["mean_curve"]) == 4
        # The goal-image SSIM beside the ground-truth distance (pooled over 2 episodes x 4 steps).
        assert len(stats["goal_ssim_curve"]) == 4 and 0 < stats["final_goal_ssim"] <= 1
        assert math.isfinite(stats["goal_ssim_spearman"]) and -1 <= stats["goal_ssim_spearman"] <= 1
    # Same episodes for every method: identical start distances.
    starts = {round(s["mean_curve"][0], 9) for s in summary["comparison"].values()}
    assert len(starts) == 1
    with Image.open(tmp_path / "rearrangement.png") as plot_image:
        assert plot_image.size[0] > 100
    report = (tmp_path / "rearrangement.md").read_text()
    assert "| N | geom_gen |" in report and "| final SSIM | rho(SSIM, distance) |" in report
    assert (
        json.loads((tmp_path / "rearrangement.json").read_text())["summary"].keys()
        == summary.keys()
    )
    video = iio.imread(tmp_path / f"rearrangement_seed{settings.first_seed}.gif")
    assert 1 <= video.shape[0] <= 4  # T + 1 frames (the GIF writer merges identical ones)
    assert video.shape[2] > 2 * video.shape[1] * 0.9
    # A rerun (as after an interruption) takes every finished episode from the store.
    episodes = sum(stats["episodes"] for cell in summary.values() for stats in cell.values())
    assert len(list((tmp_path / "episodes").rglob("*.npz"))) == episodes
    monkeypatch.setattr(runner, "run_jobs", None)  # no episode may run again
    (tmp_path / f"rearrangement_seed{settings.first_seed}.gif").unlink()
    assert evaluate_rearrangement(tiny_kinet(), settings, tmp_path, True)["summary"] == summary
    assert (iio.imread(tmp_path / f"rearrangement_seed{settings.first_seed}.gif") == video).all()


def test_plan_cli_prints_pushes_in_metres(tmp_path: Path, capsys, tiny_kinet) -> None:
    checkpoint = tmp_path / "kinet.pt"
    tiny_kinet().save_checkpoint(checkpoint, scene=SCENE)
    assert checkpoint_scene(checkpoint) == SCENE  # --resize: the 64 px goal to 32 px
    episode = make_episode(SCENE, TaskSettings(), 0)
    try:
        Image.fromarray(episode.start["pixels"]).save(tmp_path / "now.png")
        Image.fromarray(episode.goal_pixels).resize((64, 64)).save(tmp_path / "goal.png")
    finally:
        episode.close()
    pushes = plan.main(
        [
            "--checkpoint",
            str(checkpoint),
            "--image",
            str(tmp_path / "now.png"),
            str(tmp_path / "now.png"),
            "--goal",
            str(tmp_path / "goal.png"),
            "--candidates",
            "16",
            "--iterations",
            "2",
            "--top-k",
            "4",
            "--resize",
        ]
    )
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert lines == pushes and len(lines) == 2
    for push in lines:
        assert push["start_xy_m"] == pytest.approx([0.2 * v for v in push["normalised"][:2]])
        assert push["end_xy_m"] == pytest.approx([0.2 * v for v in push["normalised"][2:]])


def test_evaluate_entry_point_composes_eval_group(tmp_path: Path, tiny_kinet, conf_dir) -> None:
    checkpoint = tmp_path / "kinet.pt"
    tiny_kinet().save_checkpoint(checkpoint)
    overrides = [
        f"checkpoint={checkpoint}",
        "env.image_size=32",
        "eval.episodes=1",
        "eval.num_steps=2",
        "eval.num_objects=[1]",
        "eval.geometries=[train]",
        "eval.backgrounds=[]",
        "eval.workers=1",
        "eval.methods=[kinet_graph,random]",
        "eval.generalization_episodes=1",
        "eval.planner.num_candidates=8",
        "eval.planner.top_k=2",
        "eval.planner.optim_steps=1",
    ]
    with initialize_config_dir(str(conf_dir), version_base="1.3"):
        cfg = compose("config", overrides=overrides)
    summary = evaluate(cfg, tmp_path)["summary"]
    assert set(summary) == {"comparison", "n1_geom_train"}
    assert (tmp_path / "rearrangement" / "rearrangement.md").is_file()


def test_image_policies_are_never_handed_ground_truth(monkeypatch, tiny_kinet) -> None:
    """Every KINet method's policy sees only images and goal images, though the episodes'
    tensordict holds the simulator's object state; the GT-state oracle sees positions."""
    from kinet_rl.keys import GOAL_OBJECT_POS, GOAL_PIXELS, OBJECT_POS, PIXELS
    from kinet_rl.rearrangement.policies import PlannerPolicy
    from kinet_rl.rearrangement.runner import Job, run_jobs

    seen: list[set] = []
    forward = PlannerPolicy.forward
    monkeypatch.setattr(
        PlannerPolicy,
        "forward",
        lambda self, td: seen.append(set(td.keys(True, True))) or forward(self, td),
    )
    settings = RearrangementSettings(
        scene=SceneSettings(image_size=32), task=TaskSettings(num_steps=2), workers=1, videos=0,
        planner={"planning_horizon": 1, "optim_steps": 1, "num_candidates": 8, "top_k": 2},
    )  # fmt: skip
    condition = settings.conditions(generalization=False)[0]
    kinet_methods = [name for name, method in METHODS.items() if method.objective is not None]
    for name in kinet_methods:
        run_jobs([Job(condition, name, 10_000, False)], settings, tiny_kinet())
    assert seen == [{PIXELS, GOAL_PIXELS}] * (2 * len(kinet_methods))
    seen.clear()
    run_jobs([Job(condition, "oracle", 10_000, False)], settings, None)
    assert seen == [{OBJECT_POS, GOAL_OBJECT_POS}] * 2


def test_batched_episodes_run_as_they_do_one_at_a_time(tiny_kinet) -> None:
    """Three episodes in lockstep (one batched plan per step) push as each does alone."""
    from kinet_rl.rearrangement.runner import run_rearrangement

    settings = RearrangementSettings(
        scene=SCENE, task=TaskSettings(num_steps=4), episodes=3, workers=1, videos=1,
        methods=("kinet_keypoints_l2", "oracle", "random"),
        planner={"planning_horizon": 1, "optim_steps": 2, "num_candidates": 16, "top_k": 4},
    )  # fmt: skip
    model = tiny_kinet()
    alone = run_rearrangement(model, settings).episodes
    together = run_rearrangement(model, replace(settings, batch_episodes=3)).episodes
    for condition, by_method in alone.items():
        for method, results in by_method.items():
            for one, batched in zip(results, together[condition][method], strict=True):
                assert one.seed == batched.seed
                np.testing.assert_allclose(batched.distances, one.distances, atol=1e-6)
                assert len(batched.frames) == len(one.frames)  # the recorded video, too
    (comparison,) = alone.values()
    finals = {m: [r.distances[-1] for r in rs] for m, rs in comparison.items()}
    assert len(set(finals["random"])) == 3  # the episodes differ: the test compares something


@pytest.mark.ycb
def test_episodes_of_held_out_ycb_objects_draw_only_those() -> None:
    held_out = ("004_sugar_box", "007_tuna_fish_can", "025_mug")
    scene = SceneSettings(task="ycb", image_size=32, ycb_objects=held_out)
    episode = make_episode(scene, TaskSettings(goal_pushes=2, min_goal_distance=0.01), 50000)
    try:
        assert set(episode.env.task.active) == {f"ycb_{name}" for name in held_out}
    finally:
        episode.close()
