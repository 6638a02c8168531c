"""Runs rearrangement episodes of each method, in parallel workers, and returns the results.

Every episode is a job ``(condition, method, seed)``; up to ``batch_episodes`` jobs of one
condition and method run together in lockstep, planned in one batched planner call per step
(:func:`~kinet_rl.rearrangement.episodes.run_episodes`). Batches run in a ``spawn`` process pool
(each worker rebuilds the model from its weights once and uses one torch thread) or inline with
``workers <= 1``; the workers ignore Ctrl-C, and an interrupted run terminates them. Episode
``i`` of a condition uses seed ``first_seed + i`` (by split) for its scene and goal, the same for
every method, so methods are compared on identical episodes. Finished episodes can be kept on
disk (:mod:`kinet_rl.rearrangement.store`) so that an interrupted evaluation resumes. Writing
reports is the caller's (:mod:`kinet_rl.rearrangement.report`).
"""

from __future__ import annotations

import functools
import importlib
import logging
import multiprocessing
import multiprocessing.pool
from collections.abc import Iterable, Sequence
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import torch
from tqdm import tqdm

from kinet_rl.interrupts import worker_processes
from kinet_rl.models.checkpointing import ConfigCheckpointMixin
from kinet_rl.rearrangement.episodes import Episode, make_episode, run_episodes
from kinet_rl.rearrangement.methods import METHODS, MethodContext, check_methods, check_model
from kinet_rl.rearrangement.results import EpisodeResult, RearrangementResults
from kinet_rl.rearrangement.settings import Condition, RearrangementSettings
from kinet_rl.rearrangement.store import EpisodeStore

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Job:
    """One episode to run."""

    condition: Condition
    method: str
    seed: int
    record: bool

    @property
    def name(self) -> str:
        """The episode's name in an :class:`EpisodeStore`."""
        return f"{self.condition.name}/{self.method}/seed{self.seed}"


_WORKER_MODEL: torch.nn.Module | None = None


def _model_payload(model: torch.nn.Module) -> dict[str, Any]:
    """What a worker needs to rebuild ``model`` (KINet or a baseline): class, config, weights."""
    model_class = type(model)
    return {
        "class": (model_class.__module__, model_class.__qualname__),
        "config": dict(cast(ConfigCheckpointMixin, model).config),
        "state_dict": {k: v.cpu() for k, v in model.state_dict().items()},
    }


def _init_worker(payload: dict[str, Any] | None) -> None:
    global _WORKER_MODEL
    torch.set_num_threads(1)
    if payload is not None:
        module, name = payload["class"]
        _WORKER_MODEL = getattr(importlib.import_module(module), name)(**payload["config"])
        _WORKER_MODEL.load_state_dict(payload["state_dict"])
        _WORKER_MODEL.eval()


def run_jobs(
    jobs: Sequence[Job], settings: RearrangementSettings, model: torch.nn.Module | None
) -> list[EpisodeResult]:
    """Runs the episodes of ``jobs`` (one condition and method) together with ``model``."""
    condition, method_name = jobs[0].condition, jobs[0].method
    if any((job.condition, job.method) != (condition, method_name) for job in jobs):
        raise ValueError("run_jobs runs episodes of one condition and method together.")
    episodes: list[Episode] = []
    try:
        for job in jobs:
            episodes.append(make_episode(condition.scene, settings.task, job.seed))
        method = METHODS[method_name]
        seeds = tuple(job.seed for job in jobs)
        policy = method.policy(MethodContext(model, condition.scene, settings, seeds))
        return run_episodes(
            episodes, policy, method_name, settings.task, record=[job.record for job in jobs]
        )
    finally:
        for episode in episodes:
            episode.close()


def _run_jobs_in_worker(
    args: tuple[list[Job], RearrangementSettings],
) -> list[tuple[Job, EpisodeResult]]:
    jobs, settings = args
    return list(zip(jobs, run_jobs(jobs, settings, _WORKER_MODEL), strict=True))


def batches(jobs: Iterable[Job], size: int) -> list[list[Job]]:
    """``jobs`` in order, cut into runs of at most ``size`` of one condition and method."""
    out: list[list[Job]] = []
    for job in jobs:
        last = out[-1] if out else None
        if (
            last
            and len(last) < size
            and (last[0].condition, last[0].method)
            == (
                job.condition,
                job.method,
            )
        ):
            last.append(job)
        else:
            out.append([job])
    return out


def make_jobs(settings: RearrangementSettings, conditions: Iterable[Condition]) -> list[Job]:
    """All episodes of all conditions; the first ``videos`` ``kinet_method`` comparison episodes are recorded."""
    jobs = []
    for condition in conditions:
        for method in condition.methods:
            for i in range(condition.episodes):
                record = (
                    condition.role == "comparison"
                    and method == settings.kinet_method
                    and i < settings.videos
                )
                jobs.append(Job(condition, method, settings.first_seed + i, record))
    return jobs


def _outcomes(jobs: list[Job], settings: RearrangementSettings, model: torch.nn.Module | None):
    """``(job, result)`` of every job, batch by batch as they finish."""
    groups = batches(jobs, settings.batch_episodes)
    if settings.workers <= 1 or not jobs:
        for group in groups:
            yield from zip(group, run_jobs(group, settings, model), strict=True)
        return
    payload = None if model is None else _model_payload(model)
    start = functools.partial(
        multiprocessing.get_context("spawn").Pool,
        settings.workers,
        initializer=_init_worker,
        initargs=(payload,),
    )
    with worker_processes(start, _stop_pool) as pool:
        for finished in pool.imap_unordered(_run_jobs_in_worker, [(g, settings) for g in groups]):
            yield from finished


def _stop_pool(pool: multiprocessing.pool.Pool) -> None:
    pool.terminate()
    pool.join()


def run_rearrangement(
    model: torch.nn.Module | None,
    settings: RearrangementSettings,
    generalization: bool = False,
    progress: bool = False,
    store_dir: Path | None = None,
) -> RearrangementResults:
    """Runs the rearrangement evaluation; checks every method and the model before any episode.

    Args:
        model: Trained KINet, or a baseline for method ``model_mpc`` (None: only methods that
            need no model, ``random`` and ``oracle``, can run).
        settings: The evaluation's settings.
        generalization: Also run the Table II cells and extra backgrounds.
        progress: Show a progress bar over episodes.
        store_dir: Keeps every finished episode there (:class:`EpisodeStore`), so that a rerun
            after an interruption runs only the missing episodes; None keeps nothing.
    """
    check_methods(settings)
    conditions = settings.conditions(generalization)
    check_model(conditions, model)
    jobs = make_jobs(settings, conditions)
    episodes: dict[Condition, dict[str, list[EpisodeResult]]] = {
        c: {method: [] for method in c.methods} for c in conditions
    }
    store = None if store_dir is None else EpisodeStore(store_dir, settings, model)
    todo = []
    for job in jobs:
        stored = None if store is None else store.load(job.name)
        if stored is None:
            todo.append(job)
        else:
            episodes[job.condition][job.method].append(stored)
    if store is not None and len(todo) < len(jobs):
        log.info(
            "Resuming: %d of %d episodes are in %s", len(jobs) - len(todo), len(jobs), store.dir
        )
    with (
        closing(_outcomes(todo, settings, model)) as outcomes,  # closing stops the workers
        tqdm(
            total=len(jobs),
            initial=len(jobs) - len(todo),
            desc="rearrangement episodes",
            disable=not progress,
        ) as bar,
    ):
        for job, result in outcomes:
            if store is not None:
                store.save(job.name, result)
            episodes[job.condition][job.method].append(result)
            bar.update()
    for by_method in episodes.values():
        for results in by_method.values():
            results.sort(key=lambda r: r.seed)
    labels = {name: METHODS[name].label for c in conditions for name in c.methods}
    return RearrangementResults(settings, episodes, labels)
