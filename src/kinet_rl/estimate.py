"""What a training run will do, and how long it will take on this machine.

``python -m kinet_rl.train`` logs this plan before any work: the datasets it collects (episodes,
workers, which are complete or partial), the training steps and batch, the evaluation that
follows, the device, and a wall-time estimate measured here and now (unless ``estimate=false``),
plus the smaller ``+scale=cpu`` with its own estimate when that is worth knowing.

Time model (:func:`collection_seconds`, :func:`training_seconds`). The rates are measured just
before the run, in this process: one reset and a few pushes of the run's env with the
random-push policy (:func:`measure_pushes`), and a few optimiser steps of the run's model and
loss at its batch size on its device, on the pushes just simulated (:func:`measure_training`):

* collecting a dataset takes ``episodes_left * (reset + pushes_per_episode * push) /
  min(workers, cores)``: each worker steps its own env on one core, and workers beyond the
  machine's cores share them. Worker start-up, redrawn unstable episodes and other jobs on the
  machine are not counted; generalization sets are timed with the main scene's rates.
* training takes ``steps_left * step + validations * val_batches * validation_batch``; the
  report each validation writes (keypoint accuracy, forward error, images) is not counted.
* the final evaluation (test report, rearrangement episodes) is listed but not timed.
"""

from __future__ import annotations

import functools
import os
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import torch
from torch import nn

from kinet_rl.atomic import safe_torch_load
from kinet_rl.config_schema import target_arguments
from kinet_rl.data.collection import assemble_episode, seeded_env
from kinet_rl.data.dataset import PushDataset
from kinet_rl.data.policy import RandomPushPolicy, read_workspace_half_size
from kinet_rl.data.storage import imported_metadata, stored_episodes
from kinet_rl.devices import resolve_device
from kinet_rl.envs import make_env
from kinet_rl.pipeline import ExperimentSettings, dataset_jobs
from kinet_rl.rearrangement.methods import plans_every_method
from kinet_rl.training.checkpoint import TrainingCheckpoint
from kinet_rl.training.distributed import DistContext
from kinet_rl.training.loggers import make_logger
from kinet_rl.training.loop import Trainer, TrainerSettings

#: Pushes timed (one episode of this many; more if the trainer's windows need them).
PROBE_PUSHES = 8
#: Optimiser steps timed, after one warm-up step.
PROBE_STEPS = 2
#: Episodes tried for a stable probe episode.
PROBE_TRIES = 3
#: A run estimated to take longer than this gets the smaller scale named beside it.
LONG_RUN_SECONDS = 3600.0
#: The smaller scale that fits a laptop (``conf/scale/cpu.yaml``).
SMALLER_SCALE = "+scale=cpu"


@dataclass(frozen=True)
class MeasuredRates:
    """Seconds per unit of work, measured on this machine.

    Attributes:
        reset: One episode reset (object placement, first frame).
        push: One push (policy, physics until the scene settles, one frame).
        train_step: One optimiser step at the run's batch size, on its device.
        validation_batch: One validation batch (loss without gradient).
    """

    reset: float
    push: float
    train_step: float
    validation_batch: float


@dataclass(frozen=True)
class Experiment:
    """A checked experiment and the factories of its untrained model and its loss."""

    settings: ExperimentSettings
    build_model: Callable[[], nn.Module]
    build_loss: Callable[[nn.Module], nn.Module]


def available_cores() -> int:
    """CPU cores this process may run on."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def collection_seconds(
    episodes: int, pushes_per_episode: int, workers: int, cores: int, rates: MeasuredRates
) -> float:
    """Wall time of collecting ``episodes`` episodes with ``workers`` workers on ``cores`` cores."""
    per_episode = rates.reset + pushes_per_episode * rates.push
    return episodes * per_episode / max(1, min(workers, cores))


def validations(trained: int, steps: int, eval_every: int) -> int:
    """Validations a run makes on its way from step ``trained`` to ``steps`` (every
    ``eval_every`` steps, and at the last step)."""
    if steps <= trained:
        return 0
    periodic = steps // eval_every - trained // eval_every
    return periodic + (steps % eval_every != 0)


def training_seconds(trainer: TrainerSettings, trained: int, rates: MeasuredRates) -> float:
    """Wall time of training from step ``trained`` to ``trainer.steps``, validations included."""
    steps_left = max(0, trainer.steps - trained)
    checks = validations(trained, trainer.steps, trainer.eval_every)
    return steps_left * rates.train_step + checks * trainer.val_batches * rates.validation_batch


def format_duration(seconds: float) -> str:
    """A duration for people: ``40 s``, ``12 min``, ``1 h 47 min``."""
    if seconds < 90:
        return f"{max(1, round(seconds))} s"
    minutes = round(seconds / 60)
    if minutes < 90:
        return f"{minutes} min"
    hours, rest = divmod(minutes, 60)
    return f"{hours} h {rest} min" if rest else f"{hours} h"


@dataclass(frozen=True)
class DatasetPlan:
    """One dataset of a run: its size, how far it is collected, and how.

    Attributes:
        name: Dataset name.
        num_episodes: Episodes of the finished dataset.
        stored: Episodes already on disk.
        complete: Whether it is marked complete (nothing to collect).
        num_workers: Collection workers.
        pushes: Pushes per episode.
        imported: Whether it was imported (a robot's pushes: never collected).
    """

    name: str
    num_episodes: int
    stored: int
    complete: bool
    num_workers: int
    pushes: int
    imported: bool = False

    @property
    def episodes_left(self) -> int:
        """Episodes still to collect."""
        return 0 if self.complete else self.num_episodes - self.stored

    @property
    def status(self) -> str:
        """``complete``, ``partial (N done)`` or ``new``."""
        if self.imported:
            return "imported"
        if self.complete:
            return "complete"
        return f"partial ({self.stored:,} done)" if self.stored else "new"

    def seconds(self, rates: MeasuredRates, cores: int) -> float:
        """Wall time of collecting what is left (:func:`collection_seconds`)."""
        return collection_seconds(self.episodes_left, self.pushes, self.num_workers, cores, rates)


@dataclass(frozen=True)
class RunPlan:
    """What a training run will do: its datasets, training and evaluation.

    Attributes:
        settings: The experiment.
        run_dir: Its run directory.
        datasets: Its datasets in collection order.
        trained: Steps its checkpoint already holds (0 for a new run).
    """

    settings: ExperimentSettings
    run_dir: Path
    datasets: tuple[DatasetPlan, ...]
    trained: int

    @classmethod
    def of(cls, settings: ExperimentSettings, run_dir: Path) -> RunPlan:
        """The plan of ``settings`` in ``run_dir``, reading what is already on disk."""
        datasets = []
        jobs = dataset_jobs(settings.env, settings.data)
        imported = imported_metadata(jobs[0].path)
        if imported is not None:  # a robot's pushes: trained on as they are, nothing collected
            name, episodes = jobs[0].name, imported["num_episodes"]
            datasets.append(
                DatasetPlan(name, episodes, episodes, True, 0, imported["episode_length"], True)
            )
            jobs = []
        for job in jobs:
            stored, complete = stored_episodes(job.path)
            datasets.append(
                DatasetPlan(
                    name=job.name,
                    num_episodes=job.num_episodes,
                    stored=stored,
                    complete=complete,
                    num_workers=job.num_workers,
                    pushes=job.pushes_per_episode,
                )
            )
        return cls(settings, Path(run_dir), tuple(datasets), trained_steps(settings, run_dir))

    @property
    def episodes(self) -> int:
        """Episodes of all its datasets."""
        return sum(d.num_episodes for d in self.datasets)

    def is_smaller_than(self, other: RunPlan) -> bool:
        """Whether this run collects fewer episodes and trains fewer steps than ``other``."""
        steps, other_steps = self.settings.trainer.steps, other.settings.trainer.steps
        return self.episodes < other.episodes and steps < other_steps

    def seconds(self, rates: MeasuredRates, cores: int) -> tuple[float, float]:
        """Estimated wall time of its collection and of its training."""
        collection = sum(d.seconds(rates, cores) for d in self.datasets)
        return collection, training_seconds(self.settings.trainer, self.trained, rates)

    def lines(self, rates: MeasuredRates | None, cores: int) -> list[str]:
        """The plan, one line per stage, with estimates when ``rates`` are given."""
        s = self.settings
        device = resolve_device(s.device)
        lines = [f"Plan of {s.name} (run directory {self.run_dir}, training on {device}):"]
        for dataset in self.datasets:
            if dataset.imported:
                lines.append(
                    f"  {dataset.name}: {dataset.num_episodes:,} episodes x {dataset.pushes} "
                    "pushes, imported (nothing to collect)"
                )
                continue
            workers = dataset.num_workers
            at_once = f", {cores} at a time on {cores} cores" if workers > cores else ""
            line = (
                f"  collect {dataset.name}: {dataset.num_episodes:,} episodes x "
                f"{dataset.pushes} pushes, {workers} worker{'s' * (workers > 1)}{at_once}; "
                f"{dataset.status}"
            )
            if rates is not None and dataset.episodes_left:
                line += f", ~{format_duration(dataset.seconds(rates, cores))}"
            lines.append(line)
        t = s.trainer
        line = (
            f"  train {s.model_name}: {t.steps:,} steps at batch {t.batch_size}, validation every "
            f"{t.eval_every:,} steps"
        )
        if self.trained:
            line += f"; resumes at step {self.trained:,}"
        if rates is not None:
            line += f", ~{format_duration(training_seconds(t, self.trained, rates))}"
        lines.append(line)
        lines.append(f"  then evaluate (not timed): {self.evaluation()}")
        return lines

    def evaluation(self) -> str:
        """The evaluation after training, in words."""
        report = self.settings.report
        horizons = ", ".join(str(h) for h in report.horizons)
        text = f"forward error at {horizons} pushes on {report.num_sequences} test sequences"
        model_class, _ = target_arguments(self.settings.model_config, "model")
        episodes = report.rearrangement_episodes
        if self.datasets[0].imported:  # no object state, no simulator of its scene
            if not model_class.capabilities.keypoints:
                return "validation losses only (no object state, no keypoints)"
            return (
                f"reconstruction error, keypoint self-consistency at {horizons} pushes on "
                f"{report.num_sequences} test sequences (no object state)"
            )
        if model_class.capabilities.keypoints:
            text = f"keypoint accuracy, {text}"
        if episodes and plans_every_method(model_class.capabilities, self.settings.rearrangement):
            methods = len(self.settings.rearrangement.methods)
            text += f"; rearrangement, {episodes} episodes x {methods} methods"
        return text


def trained_steps(settings: ExperimentSettings, run_dir: Path) -> int:
    """Steps of the run's checkpoint in ``run_dir`` (0 without one, or with another
    experiment's, which the run itself refuses)."""
    path = TrainingCheckpoint(run_dir, settings.identity()).last_path
    if not path.is_file():
        return 0
    state = safe_torch_load(path)
    return int(state.get("step", 0)) if state.get("identity") == settings.identity() else 0


@dataclass(frozen=True)
class PushProbe:
    """A timed episode of an env: seconds per reset and per push, and its transitions.

    Attributes:
        env: The env's :func:`make_env` arguments.
        reset: Seconds of the reset.
        push: Seconds per push.
        episodes: The episode, as a dataset to time training on.
    """

    env: Mapping[str, Any]
    reset: float
    push: float
    episodes: PushDataset

    def fits(self, settings: ExperimentSettings) -> bool:
        """Whether it stands for ``settings``' env and holds its trainer's windows."""
        return dict(self.env) == dict(settings.env) and self.episodes.episode_length >= (
            probe_length(settings.trainer)
        )


def probe_length(trainer: TrainerSettings) -> int:
    """Pushes of a probe episode: :data:`PROBE_PUSHES`, or what the trainer's windows need."""
    return max(PROBE_PUSHES, trainer.steps_per_episode + trainer.horizon - 1)


def measure_pushes(settings: ExperimentSettings) -> PushProbe:
    """Times one reset and :func:`probe_length` random pushes of the run's env, as one
    collection worker runs them (policy, physics, frames).

    Raises:
        RuntimeError: :data:`PROBE_TRIES` episodes in a row went unstable.
    """
    pushes = probe_length(settings.trainer)
    env_fn = functools.partial(make_env, **{**settings.env, "max_steps": pushes})
    main = settings.main_dataset
    env = seeded_env(env_fn, main.seed, 0, 1)
    try:
        policy = RandomPushPolicy(read_workspace_half_size(env), **main.policy)
        for _ in range(PROBE_TRIES):
            start = time.perf_counter()
            state = env.reset()
            reset = time.perf_counter() - start
            start = time.perf_counter()
            rollout = env.rollout(pushes, policy, auto_reset=False, tensordict=state)
            push = (time.perf_counter() - start) / pushes
            episode = assemble_episode(rollout, pushes)
            if episode is not None:
                episodes = PushDataset.from_episodes(torch.stack([episode]))
                return PushProbe(dict(settings.env), reset, push, episodes)
    finally:
        env.close()
    raise RuntimeError(
        f"{PROBE_TRIES} probe episodes of the env went unstable; check the env's physics "
        "settings, or skip the time estimate with estimate=false."
    )


def measure_training(
    experiment: Experiment, probe: PushDataset, steps: int = PROBE_STEPS
) -> tuple[float, float]:
    """Times the run's optimiser step (after a warm-up step) and validation batch on ``probe``
    transitions, on its device; returns seconds per step and per validation batch."""
    s = experiment.settings
    device = resolve_device(s.device)
    model = experiment.build_model()
    with tempfile.TemporaryDirectory() as scratch:
        logger = make_logger("csv", scratch, s.name)
        trainer = Trainer(
            experiment.build_loss(model),
            probe,
            probe,
            replace(s.trainer, val_batches=1),
            TrainingCheckpoint(scratch, {}),
            logger,
            DistContext(device=device),
        )
        trainer.train_step()  # warm-up: allocations, kernel choice
        step = _seconds_per_call(trainer.train_step, device, steps)
        validation = _seconds_per_call(trainer.validate, device, 1)
    return step, validation


def _seconds_per_call(call: Callable[[], object], device: torch.device, calls: int) -> float:
    _synchronize(device)
    start = time.perf_counter()
    for _ in range(calls):
        call()
    _synchronize(device)
    return (time.perf_counter() - start) / calls


def _synchronize(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def measure_rates(
    experiment: Experiment, probe: PushProbe | None = None
) -> tuple[MeasuredRates, PushProbe]:
    """The rates of ``experiment`` measured here (:func:`measure_pushes`, reusing ``probe`` when
    it fits, then :func:`measure_training`), and the probe they came from."""
    if probe is None or not probe.fits(experiment.settings):
        probe = measure_pushes(experiment.settings)
    step, validation = measure_training(experiment, probe.episodes)
    return MeasuredRates(probe.reset, probe.push, step, validation), probe


def describe_run(experiment: Experiment, run_dir: Path, smaller: Experiment | None = None) -> str:
    """The plan of a run (:class:`RunPlan`), with its measured estimate if
    ``experiment.settings.estimate``, and the ``smaller`` scale's when it is worth naming: it
    trains fewer steps on fewer episodes, or the run takes over :data:`LONG_RUN_SECONDS` and
    the smaller scale is faster."""
    plan, cores = RunPlan.of(experiment.settings, run_dir), available_cores()
    small = None if smaller is None else RunPlan.of(smaller.settings, run_dir)
    if not experiment.settings.estimate:
        lines = plan.lines(None, cores)
        lines.append("  no time estimate (estimate=false)")
        if small is not None and small.is_smaller_than(plan):
            lines.append(f"  {_smaller_text(small)}")
        return "\n".join(lines)
    rates, probe = measure_rates(experiment)
    lines = plan.lines(rates, cores)
    collection, training = plan.seconds(rates, cores)
    total = collection + training
    lines.append(
        f"  estimated wall time on this machine: ~{format_duration(total)} (collection "
        f"~{format_duration(collection)}, training ~{format_duration(training)}, evaluation not "
        f"included), from {1e3 * rates.push:.0f} ms per push, {1e3 * rates.reset:.0f} ms per "
        f"reset, {rates.train_step:.3g} s per training step, {cores} CPU cores "
        "(estimate=false skips measuring)"
    )
    if small is not None and (small.is_smaller_than(plan) or total > LONG_RUN_SECONDS):
        assert smaller is not None
        small_rates, _ = measure_rates(smaller, probe)
        small_total = sum(small.seconds(small_rates, cores))
        if small_total < total:
            lines.append(f"  {_smaller_text(small)}: ~{format_duration(small_total)} here")
    return "\n".join(lines)


def _smaller_text(small: RunPlan) -> str:
    t = small.settings.trainer
    return (
        f"smaller scale that fits a laptop: add {SMALLER_SCALE} ({small.episodes:,} episodes, "
        f"{t.steps:,} steps at batch {t.batch_size})"
    )
