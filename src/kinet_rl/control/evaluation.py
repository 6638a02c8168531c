"""Rearrangement evaluation: episodes of each method in parallel workers, summaries and a report.

Every episode is a job ``(condition, method, seed)``; jobs run in a ``spawn`` process pool
(each worker rebuilds the model from its weights once and uses one torch thread) or inline with
``workers <= 1``. Episode ``i`` of a condition uses seed ``seed + i`` for its scene and goal,
the same for every method, so methods are compared on identical episodes.
"""

from __future__ import annotations

import importlib
import logging
import multiprocessing
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch

from kinet_rl.control.rearrange import (
    BASELINE_METHODS,
    METHODS,
    EpisodeResult,
    KINetController,
    OracleController,
    RandomController,
    SceneSettings,
    TaskSettings,
    make_episode,
    run_episode,
)
from kinet_rl.control.robot import PushPlanner
from kinet_rl.envs.workspace import workspace_for
from kinet_rl.models import KINetWorldModel
from kinet_rl.models.checkpointing import ConfigCheckpointMixin

logger = logging.getLogger(__name__)

#: GraphMPC methods: the paper's similarity ``S`` and the node-embedding distance.
KINET_GRAPH_METHODS = ("kinet_graph", "kinet_graph_distance")
KINET_REWARDS = {
    "kinet_graph": "graph",
    "kinet_graph_distance": "graph_distance",
    "kinet_keypoints": "keypoints",
}


@dataclass(frozen=True)
class Condition:
    """A named scene on which some methods are evaluated."""

    name: str
    scene: SceneSettings
    methods: tuple[str, ...]
    episodes: int


@dataclass(frozen=True)
class RearrangementSettings:
    """Settings of :func:`evaluate_rearrangement` (mirrors ``conf/eval/rearrange.yaml``).

    Attributes:
        scene: The training scene (comparisons run on it).
        task: Task and metric settings.
        episodes: Episodes per method in the comparison.
        methods: Methods of the comparison (subset of ``METHODS``).
        planner: :class:`GraphMPCPlanner` settings of the KINet controllers.
        oracle_planner: Planner settings of the oracle (its model is cheap).
        oracle_contact_radius: Object-plus-pusher radius of the oracle's push model, metres.
        num_objects: Object counts of the generalization table (empty: skipped).
        geometries: Geometries of the generalization table.
        backgrounds: Extra backgrounds to test (e.g. ``["random"]``; empty: skipped).
        generalization_episodes: Episodes per generalization cell.
        workers: Parallel worker processes (<= 1 runs inline).
        seed: Seed of the first episode.
        videos: Episodes of ``kinet_method`` recorded as GIFs.
        kinet_method: The KINet planner of the generalization conditions and the videos (one of
            ``KINET_GRAPH_METHODS``).
    """

    scene: SceneSettings = field(default_factory=SceneSettings)
    task: TaskSettings = field(default_factory=TaskSettings)
    episodes: int = 4
    methods: tuple[str, ...] = METHODS
    planner: Mapping[str, Any] = field(
        default_factory=lambda: {
            "planning_horizon": 1,
            "optim_steps": 3,
            "num_candidates": 64,
            "top_k": 8,
        }
    )
    oracle_planner: Mapping[str, Any] = field(
        default_factory=lambda: {
            "planning_horizon": 1,
            "optim_steps": 5,
            "num_candidates": 256,
            "top_k": 16,
        }
    )
    oracle_contact_radius: float = 0.035
    num_objects: tuple[int, ...] = ()
    geometries: tuple[str, ...] = ("train", "gen")
    backgrounds: tuple[str, ...] = ()
    generalization_episodes: int = 2
    workers: int = 2
    seed: int = 10_000
    videos: int = 1
    kinet_method: str = "kinet_graph_distance"

    def __post_init__(self) -> None:
        if self.kinet_method not in KINET_GRAPH_METHODS:
            raise ValueError(
                f"kinet_method={self.kinet_method!r}; choose one of {list(KINET_GRAPH_METHODS)}."
            )
        unknown = [m for m in self.methods if m not in METHODS + BASELINE_METHODS]
        if unknown:
            raise ValueError(
                f"Unknown methods {unknown}; choose from {list(METHODS + BASELINE_METHODS)}."
            )
        if self.episodes < 1 or self.task.num_steps < 1:
            raise ValueError("episodes and task.num_steps must be at least 1.")

    @classmethod
    def from_dicts(
        cls, eval_cfg: Mapping[str, Any], env_cfg: Mapping[str, Any]
    ) -> RearrangementSettings:
        """Builds settings from plain dicts: the ``eval`` group and the ``env`` group of a run."""
        scene_names = {f.name for f in fields(SceneSettings)}
        task_names = {f.name for f in fields(TaskSettings)}
        scene = SceneSettings(**{k: v for k, v in env_cfg.items() if k in scene_names})
        task = TaskSettings(**{k: v for k, v in eval_cfg.items() if k in task_names})
        own = {f.name for f in fields(cls)} - {"scene", "task"}
        unknown = set(eval_cfg) - own - task_names
        if unknown:
            raise ValueError(
                f"Unknown rearrangement settings {sorted(unknown)}; allowed: {sorted(own | task_names)}."
            )
        kwargs = {k: v for k, v in eval_cfg.items() if k in own}
        for key in ("methods", "num_objects", "geometries", "backgrounds"):
            if key in kwargs:
                kwargs[key] = tuple(kwargs[key] or ())
        for key in ("planner", "oracle_planner"):
            if key in kwargs:
                kwargs[key] = dict(kwargs[key])
        return cls(scene=scene, task=task, **kwargs)

    def as_dict(self) -> dict[str, Any]:
        """Plain-container form (for JSON)."""
        out = asdict(self)
        out["planner"] = dict(self.planner)
        out["oracle_planner"] = dict(self.oracle_planner)
        return out

    def conditions(self, generalization: bool = True) -> list[Condition]:
        """The comparison, then (if ``generalization``) the Table II cells and backgrounds."""
        out = [Condition("comparison", self.scene, self.methods, self.episodes)]
        if not generalization:
            return out
        for geometry in self.geometries if self.scene.task == "blocks" else ("train",):
            for n in self.num_objects:
                scene = replace(self.scene, num_objects=n, geometry=geometry)
                out.append(
                    Condition(
                        f"n{n}_geom_{geometry}",
                        scene,
                        (self.kinet_method,),
                        self.generalization_episodes,
                    )
                )
        for background in self.backgrounds:
            scene = replace(self.scene, background=background)
            out.append(
                Condition(
                    f"background_{background}",
                    scene,
                    (self.kinet_method, "random"),
                    self.generalization_episodes,
                )
            )
        return out


@dataclass(frozen=True)
class Job:
    """One episode to run."""

    condition: str
    method: str
    seed: int
    scene: SceneSettings
    record: bool


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


def make_controller(
    method: str,
    model: torch.nn.Module | None,
    scene: SceneSettings,
    settings: RearrangementSettings,
    seed: int,
):
    """The controller of ``method`` for one episode, seeded by ``seed``."""
    if method == "random":
        return RandomController(seed)
    if method == "oracle":
        return OracleController(
            scene, dict(settings.oracle_planner), settings.oracle_contact_radius, seed
        )
    if method in BASELINE_METHODS:
        if model is None:
            raise ValueError(f"Method {method!r} needs a trained baseline model; pass model=.")
        from kinet_rl.baselines.model_env import BaselineMPCController

        return BaselineMPCController(model, settings.planner, seed)
    if model is None:
        raise ValueError(f"Method {method!r} needs a trained KINet model; pass model=.")
    if not isinstance(model, KINetWorldModel):
        raise TypeError(
            f"Method {method!r} plans with KINet, got a {type(model).__name__}; use method "
            "'model_mpc' for baseline models."
        )
    half_size = workspace_for(scene.task).half_size
    planner = PushPlanner(
        model, half_size, reward=KINET_REWARDS[method], seed=seed, **dict(settings.planner)
    )
    return KINetController(planner)


def _run_job(
    job: Job, settings: RearrangementSettings, model: torch.nn.Module | None
) -> EpisodeResult:
    episode = make_episode(job.scene, settings.task, job.seed)
    try:
        controller = make_controller(job.method, model, job.scene, settings, job.seed)
        return run_episode(episode, controller, job.method, settings.task, record=job.record)
    finally:
        episode.close()


def _run_job_in_worker(args: tuple[Job, RearrangementSettings]) -> tuple[Job, EpisodeResult]:
    job, settings = args
    return job, _run_job(job, settings, _WORKER_MODEL)


def make_jobs(settings: RearrangementSettings, conditions: Iterable[Condition]) -> list[Job]:
    """All episodes of all conditions; the first ``videos`` ``kinet_method`` comparison episodes are recorded."""
    jobs = []
    for condition in conditions:
        for method in condition.methods:
            for i in range(condition.episodes):
                record = (
                    condition.name == "comparison"
                    and method == settings.kinet_method
                    and i < settings.videos
                )
                jobs.append(Job(condition.name, method, settings.seed + i, condition.scene, record))
    return jobs


def run_jobs(
    jobs: list[Job],
    settings: RearrangementSettings,
    model: torch.nn.Module | None,
    progress: bool = False,
) -> dict[str, dict[str, list[EpisodeResult]]]:
    """Runs ``jobs`` (in parallel with ``settings.workers`` > 1); results by condition and method."""
    from tqdm import tqdm

    results: dict[str, dict[str, list[EpisodeResult]]] = {}
    bar = tqdm(total=len(jobs), desc="rearrangement episodes", disable=not progress)
    if settings.workers <= 1:
        outcomes = ((job, _run_job(job, settings, model)) for job in jobs)
        for job, result in outcomes:
            results.setdefault(job.condition, {}).setdefault(job.method, []).append(result)
            bar.update()
    else:
        payload = None if model is None else _model_payload(model)
        context = multiprocessing.get_context("spawn")
        with context.Pool(settings.workers, initializer=_init_worker, initargs=(payload,)) as pool:
            for job, result in pool.imap_unordered(
                _run_job_in_worker, [(j, settings) for j in jobs]
            ):
                results.setdefault(job.condition, {}).setdefault(job.method, []).append(result)
                bar.update()
    bar.close()
    for by_method in results.values():
        for episodes in by_method.values():
            episodes.sort(key=lambda r: r.seed)
    return results


def summarize(episodes: list[EpisodeResult]) -> dict[str, Any]:
    """Mean and standard error of the distance curve, final distance and success rate."""
    curves = np.stack([r.distances for r in episodes])  # [E, T + 1]
    n = len(episodes)
    sem = curves.std(0, ddof=1) / np.sqrt(n) if n > 1 else np.zeros(curves.shape[1])
    return {
        "episodes": n,
        "mean_curve": curves.mean(0).tolist(),
        "sem_curve": sem.tolist(),
        "initial_distance": float(curves[:, 0].mean()),
        "final_distance": float(curves[:, -1].mean()),
        "final_distance_sem": float(sem[-1]),
        "success_rate": float(np.mean([r.success for r in episodes])),
        "unstable": int(sum(r.unstable for r in episodes)),
    }


def evaluate_rearrangement(
    model: torch.nn.Module | None,
    settings: RearrangementSettings | Mapping[str, Any],
    out_dir: str | Path,
    generalization: bool = False,
    progress: bool = False,
) -> dict[str, Any]:
    """Runs the rearrangement evaluation and writes ``rearrangement.png``, ``.md`` and ``.json``.

    Args:
        model: Trained KINet, or a baseline for method ``model_mpc`` (None: only the
            ``random`` and ``oracle`` methods can run).
        settings: :class:`RearrangementSettings`, or a dict with ``eval`` and ``env`` entries
            (plain containers, e.g. ``OmegaConf.to_container(cfg)``).
        out_dir: Folder of the outputs (created).
        generalization: Also run the Table II cells and extra backgrounds.
        progress: Show a progress bar over episodes.

    Returns:
        ``{"summary": {condition: {method: stats}}, "settings": ..., "files": [...]}``; the
        comparison's stats include ``final_distance`` (metres) and ``success_rate``.
    """
    from kinet_rl.control.report import write_report

    if not isinstance(settings, RearrangementSettings):
        settings = RearrangementSettings.from_dicts(
            settings.get("eval", {}), settings.get("env", {})
        )
    conditions = settings.conditions(generalization)
    if model is None:
        needs = sorted(
            {m for c in conditions for m in c.methods if m in (*KINET_REWARDS, *BASELINE_METHODS)}
        )
        if needs:
            raise ValueError(f"Methods {needs} need a model; pass model= or drop them.")
    results = run_jobs(make_jobs(settings, conditions), settings, model, progress=progress)
    summary = {
        cond: {method: summarize(eps) for method, eps in by_method.items()}
        for cond, by_method in results.items()
    }
    files = write_report(Path(out_dir), settings, summary, results)
    logger.info("Rearrangement evaluation written to %s", out_dir)
    return {"summary": summary, "settings": settings.as_dict(), "files": [str(f) for f in files]}
