"""The run plan and its time arithmetic, with fixed rates (nothing is measured here)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, cast

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from kinet_rl.atomic import atomic_write_json
from kinet_rl.data.storage import METADATA_FILE, PROGRESS_FILE
from kinet_rl.estimate import (
    SMALLER_SCALE,
    DatasetPlan,
    MeasuredRates,
    RunPlan,
    collection_seconds,
    describe_run,
    format_duration,
    training_seconds,
    validations,
)
from kinet_rl.pipeline import ExperimentSettings
from kinet_rl.train import experiment, smaller_experiment
from kinet_rl.training.loop import TrainerSettings

RATES = MeasuredRates(reset=0.5, push=0.1, train_step=0.2, validation_batch=0.05)


def settings(conf_dir: Path, tmp_path: Path, *overrides: str) -> ExperimentSettings:
    return experiment_of(conf_dir, tmp_path, *overrides).settings


def experiment_of(conf_dir: Path, tmp_path: Path, *overrides: str):
    with initialize_config_dir(str(conf_dir), version_base="1.3"):
        cfg = compose(config_name="config", overrides=[*overrides, f"data.root={tmp_path}"])
    return experiment(cfg)


def test_collection_runs_as_many_workers_at_once_as_there_are_cores() -> None:
    # 100 episodes x (reset 0.5 s + 60 pushes x 0.1 s) = 650 s of work.
    assert collection_seconds(100, 60, workers=1, cores=2, rates=RATES) == pytest.approx(650)
    assert collection_seconds(100, 60, workers=2, cores=2, rates=RATES) == pytest.approx(325)
    assert collection_seconds(100, 60, workers=16, cores=2, rates=RATES) == pytest.approx(325)
    assert collection_seconds(100, 60, workers=16, cores=8, rates=RATES) == pytest.approx(81.25)
    assert collection_seconds(0, 60, workers=2, cores=2, rates=RATES) == 0


def test_validations_are_counted_every_eval_every_steps_and_at_the_end() -> None:
    assert validations(0, 6, 3) == 2  # steps 3, 6
    assert validations(0, 7, 3) == 3  # steps 3, 6, 7
    assert validations(6, 9, 3) == 1  # a resumed run: step 9
    assert validations(4, 10, 5) == 2  # steps 5, 10
    assert validations(9, 9, 3) == 0  # already trained


def test_training_time_counts_steps_left_and_validation_batches() -> None:
    trainer = TrainerSettings(steps=1000, eval_every=250, val_batches=8)
    # 1000 steps x 0.2 s + 4 validations x 8 batches x 0.05 s
    assert training_seconds(trainer, 0, RATES) == pytest.approx(201.6)
    assert training_seconds(trainer, 500, RATES) == pytest.approx(100.8)
    assert training_seconds(trainer, 1000, RATES) == 0


def test_durations_read_in_seconds_minutes_and_hours() -> None:
    assert [format_duration(s) for s in (0.2, 40, 720, 6448, 7200)] == [
        "1 s",
        "40 s",
        "12 min",
        "1 h 47 min",
        "2 h",
    ]


def test_a_dataset_plan_collects_only_what_is_missing() -> None:
    new = DatasetPlan("d", 100, stored=0, complete=False, num_workers=2, pushes=60)
    partial = DatasetPlan("d", 100, stored=30, complete=False, num_workers=2, pushes=60)
    done = DatasetPlan("d", 100, stored=100, complete=True, num_workers=2, pushes=60)
    assert [p.status for p in (new, partial, done)] == ["new", "partial (30 done)", "complete"]
    assert [p.seconds(RATES, cores=2) for p in (new, partial, done)] == pytest.approx(
        [325, 227.5, 0]
    )


def test_the_plan_reads_which_datasets_are_complete_or_partial(
    conf_dir: Path, tmp_path: Path
) -> None:
    s = settings(conf_dir, tmp_path, "+exp=smoke")
    atomic_write_json(tmp_path / "smoke" / PROGRESS_FILE, {"committed": 4})
    atomic_write_json(tmp_path / "smoke_2obj" / METADATA_FILE, {"num_episodes": 2})
    plan = RunPlan.of(s, tmp_path / "run")
    assert [(d.name, d.stored, d.status) for d in plan.datasets] == [
        ("smoke", 4, "partial (4 done)"),
        ("smoke_2obj", 2, "complete"),
    ]
    collection, training = plan.seconds(RATES, cores=2)
    # 6 episodes left x (0.5 s + 5 pushes x 0.1 s), 1 worker; 6 steps and 2 validations of 1 batch
    assert collection == pytest.approx(6.0)
    assert training == pytest.approx(6 * 0.2 + 2 * 0.05)
    lines = plan.lines(RATES, cores=2)
    assert lines[1] == "  collect smoke: 10 episodes x 5 pushes, 1 worker; partial (4 done), ~6 s"
    assert lines[2] == "  collect smoke_2obj: 2 episodes x 5 pushes, 1 worker; complete"
    assert lines[3].startswith("  train KINetWorldModel: 6 steps at batch 4")


def test_the_paper_scale_names_the_cpu_scale_and_the_small_runs_do_not(
    conf_dir: Path, tmp_path: Path
) -> None:
    paper = experiment_of(conf_dir, tmp_path, "+exp=blocks_topview", "estimate=false")
    cpu = experiment_of(conf_dir, tmp_path, "+exp=blocks_topview", "estimate=false", "+scale=cpu")
    text = describe_run(paper, tmp_path / "run", cpu)
    assert "collect blocks_topview: 8,000 episodes x 60 pushes, 16 workers" in text
    assert "50,000 steps at batch 64" in text and "no time estimate (estimate=false)" in text
    assert f"add {SMALLER_SCALE} (1,250 episodes, 10,000 steps at batch 32)" in text
    smoke = experiment_of(conf_dir, tmp_path, "+exp=smoke", "estimate=false")
    smoke_cpu = experiment_of(conf_dir, tmp_path, "+exp=smoke", "estimate=false", "+scale=cpu")
    assert SMALLER_SCALE not in describe_run(smoke, tmp_path / "run", smoke_cpu)


def test_estimate_must_be_a_boolean(conf_dir: Path, tmp_path: Path) -> None:
    with initialize_config_dir(str(conf_dir), version_base="1.3"):
        cfg = compose(config_name="config", overrides=["estimate=maybe"])
    container = cast(dict[str, Any], OmegaConf.to_container(cfg, resolve=True))
    with pytest.raises(ValueError, match="estimate: got 'maybe', expected true or false"):
        ExperimentSettings.from_container(container)


def test_a_smaller_scale_that_does_not_fit_the_overrides_is_not_named(conf_dir: Path) -> None:
    # steps_per_episode=64 divides the run's batch of 64, not the cpu scale's 32.
    overrides = ["+exp=blocks_topview", "trainer.steps_per_episode=64", "env.max_steps=70"]
    with initialize_config_dir(str(conf_dir), version_base="1.3"):
        run = compose(config_name="config", overrides=overrides)
        smaller = compose(config_name="config", overrides=[*overrides, SMALLER_SCALE])
    experiment(run)  # the run itself is valid
    assert smaller_experiment(smaller) is None and smaller_experiment(None) is None
