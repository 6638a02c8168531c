"""End-to-end ``python -m kinet_rl.train +exp=smoke``: outputs, resumption, torchrun DDP (slow)."""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir

from kinet_rl import evaluate
from kinet_rl.atomic import CheckpointError
from kinet_rl.baselines import ObjectCountError, ObjectInteractionModel, VCDNWorldModel
from kinet_rl.data import load_dataset
from kinet_rl.envs import SceneGeometry, SceneSettings
from kinet_rl.evaluation.forward import forward_errors
from kinet_rl.models import KINetWorldModel
from kinet_rl.models.checkpointing import checkpoint_scene

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]


def run_train(tmp: Path, *overrides: str, launcher: tuple[str, ...] = ("-m",)) -> str:
    """Runs the smoke experiment with data and run directory in ``tmp``; returns its output."""
    command = [
        sys.executable,
        *launcher,
        "kinet_rl.train",
        "+exp=smoke",
        f"data.root={tmp / 'data'}",
        f"hydra.run.dir={tmp / 'run'}",
        *overrides,
    ]
    env = {
        **os.environ,
        "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
        "OMP_NUM_THREADS": "1",
        "PYTHONUNBUFFERED": "1",  # stdout (logs) and stderr (progress bars) in the order written
    }
    result = subprocess.run(
        command,
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stdout[-6000:]
    return result.stdout


#: The first run's output, kept beside its data and run directory.
FIRST_OUTPUT = "first_run_output.txt"


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("train")
    output = run_train(tmp)  # also collects smoke_2obj, a 2-object generalization set
    assert "Keypoint accuracy" in output  # the report is printed at the end
    (tmp / FIRST_OUTPUT).write_text(output)
    return tmp


def test_the_plan_is_logged_before_the_first_collection(smoke_run: Path) -> None:
    output = (smoke_run / FIRST_OUTPUT).read_text()
    plan = output.index("Plan of smoke (run directory")
    first_collection = re.search(r"smoke:\s+\d+%\|", output)  # the dataset's progress bar
    assert first_collection is not None and plan < first_collection.start()
    lines = output[plan : first_collection.start()].splitlines()
    assert "  collect smoke: 10 episodes x 5 pushes, 1 worker; new, ~" in "\n".join(lines)
    assert any(line.startswith("  train KINetWorldModel: 6 steps at batch 4") for line in lines)
    (estimate,) = [line for line in lines if "estimated wall time on this machine" in line]
    per_push = float(re.search(r"from (\d+) ms per push", estimate).group(1))
    assert 0 < per_push < 1000  # a measured rate of a 32 px, 3-block push
    assert "+scale=cpu" not in output  # the cpu scale is larger than the smoke run


def test_run_writes_model_report_images_and_logs(smoke_run: Path) -> None:
    run = smoke_run / "run"
    results = json.loads((run / "results.json").read_text())
    assert results["step"] == 6
    assert 0.0 <= results["keypoint_accuracy"] <= 1.0
    assert set(results["forward_error_m"]) == {"1", "3"}
    assert "| pushes ahead |" in (run / "report.md").read_text()
    two_objects = results["held_out"]["smoke_2obj"]  # the generalization set, scored too
    assert set(two_objects["forward_error_m"]) == {"1", "3"}
    assert 0.0 <= two_objects["keypoint_accuracy"] <= 1.0
    assert two_objects["no_motion_error_m"] != results["no_motion_error_m"]
    assert "## Held-out set `smoke_2obj`" in (run / "report.md").read_text()
    for name in ("keypoints_final.png", "reconstruction_final.png", "keypoints_step000003.png"):
        assert (run / "images" / name).stat().st_size > 0
    assert list((run / "logs").rglob("*.csv")), "CSV logger wrote no scalars"
    curve = next((run / "logs").rglob("val/forward_error_1_mm.csv")).read_text().split()
    steps_and_mm = [tuple(float(v) for v in line.split(",")) for line in curve]
    assert [step for step, _ in steps_and_mm] == [3, 6]  # the learning curve, every validation
    assert all(0 < mm < 1e3 for _, mm in steps_and_mm)
    model = KINetWorldModel.from_checkpoint(run / "kinet.pt", {"num_keypoints": 6})
    assert model.detector.num_keypoints == 6
    # The experiment's validated planning travels with the model: eval.kinet_method's objective
    # and eval.planner's budget (conf/eval/rearrange.yaml), and the scene it was trained on.
    assert model.planning.objective == "keypoints_l2"
    assert model.planning.planner["num_candidates"] == 64 and model.planning.planner["return_best"]
    assert model.scene == SceneSettings(image_size=32)


def test_tensorboard_run_shows_images_and_rearrangement_gif(smoke_run: Path) -> None:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    run = smoke_run / "run_tb"
    tiny_eval = [
        "report.rearrangement_episodes=1", "eval.num_steps=2", "eval.methods=[kinet_keypoints_l2]",
        "eval.workers=1", "eval.videos=1", "eval.planner.num_candidates=8", "eval.planner.top_k=2",
        "eval.planner.optim_steps=1",
    ]  # fmt: skip
    run_train(smoke_run, "logger=tensorboard", f"hydra.run.dir={run}", *tiny_eval)
    (logdir,) = {p.parent for p in (run / "logs").rglob("events.out.tfevents.*")}
    events = EventAccumulator(str(logdir), size_guidance={"images": 0, "scalars": 0})
    events.Reload()
    assert [e.step for e in events.Scalars("val/forward_error_1_mm")] == [3, 6]
    images = {tag: events.Images(tag) for tag in events.Tags()["images"]}
    assert [e.step for e in images["val/keypoints"]] == [3, 6]
    assert [e.step for e in images["val/reconstruction"]] == [3, 6]
    # What TensorBoard shows is the PNG the run wrote, byte for byte.
    (final_keypoints,) = images["test/keypoints"]
    expected = (run / "images" / "keypoints_final.png").read_bytes()
    assert final_keypoints.encoded_image_string == expected and final_keypoints.step == 6
    (video,) = images["rearrangement/rearrangement_seed50000"]
    assert video.encoded_image_string[:6] == b"GIF89a" and video.step == 6
    gif = run / "rearrangement" / "rearrangement_seed50000.gif"
    assert video.encoded_image_string == gif.read_bytes()
    assert "rearrangement/rearrangement" in images  # the distance-to-goal plot


def test_rerun_resumes_and_longer_run_continues(smoke_run: Path) -> None:
    output = run_train(smoke_run, "trainer.steps=9")
    assert "Resumed" in output and "at step 6" in output
    assert json.loads((smoke_run / "run" / "results.json").read_text())["step"] == 9


def test_other_experiment_in_same_run_dir_is_refused(smoke_run: Path) -> None:
    command = [
        sys.executable, "-m", "kinet_rl.train", "+exp=smoke", f"data.root={smoke_run / 'data'}",
        f"hydra.run.dir={smoke_run / 'run'}", "model.num_keypoints=4",
    ]  # fmt: skip
    result = subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=300)
    assert result.returncode != 0
    assert "belongs to a different experiment" in result.stderr
    assert "model" in result.stderr


def test_mismatched_model_checkpoint_is_refused(smoke_run: Path) -> None:
    with pytest.raises(CheckpointError, match="num_keypoints"):
        KINetWorldModel.from_checkpoint(smoke_run / "run" / "kinet.pt", {"num_keypoints": 9})


def test_torchrun_two_cpu_processes(tmp_path: Path) -> None:
    run_train(
        tmp_path,
        "device=cpu",
        "data.generalization=null",
        launcher=("-m", "torch.distributed.run", "--nproc_per_node=2", "--master_port=29517", "-m"),
    )
    results = json.loads((tmp_path / "run" / "results.json").read_text())
    assert results["world_size"] == 2
    state = torch.load(tmp_path / "run" / "checkpoints" / "last.pt", weights_only=True)
    assert state["step"] == 6


def test_baseline_trains_through_the_same_pipeline(smoke_run: Path) -> None:
    run_train(smoke_run, "model=in", "loss=in", f"hydra.run.dir={smoke_run / 'run_in'}")
    results = json.loads((smoke_run / "run_in" / "results.json").read_text())
    assert results["model"] == "ObjectInteractionModel" and results["step"] == 6
    checkpoint = smoke_run / "run_in" / "model.pt"
    assert checkpoint_scene(checkpoint) == SceneSettings(image_size=32)  # the smoke scene
    # The saved weights are the evaluated ones: they reproduce the run's forward errors.
    model = ObjectInteractionModel.from_checkpoint(checkpoint).eval()
    assert model.planning.objective == "object_distance"  # its own: KINet's is not declared
    test = load_dataset(smoke_run / "data" / "smoke", "test")
    errors = forward_errors(model.object_rollout(), test, (1, 3), num_sequences=4)
    reproduced = {str(h): e["model"] for h, e in errors.items()}
    assert reproduced == pytest.approx(results["forward_error_m"], rel=1e-4)


def test_vcdn_trains_through_the_same_pipeline_and_evaluate_plans_with_it(
    smoke_run: Path, conf_dir: Path
) -> None:
    run = smoke_run / "run_vcdn"
    run_train(smoke_run, "model=vcdn", "loss=vcdn", f"hydra.run.dir={run}")
    results = json.loads((run / "results.json").read_text())
    assert results["model"] == "V-CDN" and results["step"] == 6
    assert 0.0 <= results["keypoint_accuracy"] <= 1.0
    assert (run / "images" / "reconstruction_final.png").stat().st_size > 0
    losses = {p.stem for p in (run / "logs").rglob("train/loss_*.csv")}
    assert losses == {"loss_rec", "loss_fwd", "loss_kl", "loss_rollout"}  # both stages ran
    VCDNWorldModel.from_checkpoint(run / "model.pt", {"num_keypoints": 6})
    overrides = [
        "+exp=smoke", "model=vcdn", "loss=vcdn", "eval.methods=[model_mpc,random]",
        "eval.kinet_method=model_mpc", "eval.episodes=1", "eval.num_steps=2",
        "eval.num_objects=[2]", "eval.geometries=[train]", "eval.backgrounds=[]",
        "eval.workers=1", "eval.generalization_episodes=1", "eval.videos=0",
        "eval.planner.num_candidates=8", "eval.planner.top_k=2", "eval.planner.optim_steps=1",
    ]  # fmt: skip
    with initialize_config_dir(str(conf_dir), version_base="1.3"):
        cfg = compose("config", overrides=overrides)
    summary = evaluate.evaluate(cfg, run)["summary"]  # loads <run>/model.pt
    assert set(summary) == {"comparison", "n2_geom_train"}  # V-CDN plans any object count
    assert set(summary["n2_geom_train"]) == {"model_mpc"}


def test_kinet_takes_other_object_counts_and_in_refuses_them(smoke_run: Path) -> None:
    two_objects = load_dataset(smoke_run / "data" / "smoke_2obj", "all")
    kinet = KINetWorldModel.from_checkpoint(smoke_run / "run" / "kinet.pt").eval()
    geometry = SceneGeometry.of_scene("blocks", "top", 32)
    errors = forward_errors(kinet.object_rollout(geometry), two_objects, (1,), num_sequences=4)
    model_error, no_motion = errors[1]["model"], errors[1]["no_motion"]
    assert math.isfinite(model_error) and no_motion > 0.0  # the logged pushes moved objects
    # Both objects moved by KINet's predicted keypoint motion, so its error is not the no-motion
    # one; after the smoke training that motion is push-sized (seed 0: 17.2 mm against 16.6 mm
    # with no motion, after 6 or 9 steps), while a metres/pixels or projection slip is far off.
    assert model_error != pytest.approx(no_motion, rel=1e-3)
    assert model_error < 2 * no_motion
    trained_on_three = ObjectInteractionModel(num_objects=3)
    with pytest.raises(ObjectCountError, match="3"):
        forward_errors(
            trained_on_three.object_rollout(geometry), two_objects, (1,), num_sequences=4
        )


def test_estimate_false_logs_the_plan_without_measuring(smoke_run: Path) -> None:
    output = run_train(smoke_run, "estimate=false")  # already trained: nothing left to do
    assert "  collect smoke: 10 episodes x 5 pushes, 1 worker; complete" in output
    assert re.search(r"resumes at step \d+", output)
    assert "no time estimate (estimate=false)" in output and "estimated wall time" not in output
