"""Running an experiment: collect its datasets, train (resuming), evaluate and write the run's
report (:func:`run_experiment`); the rearrangement evaluation with its written report
(:func:`evaluate_rearrangement`)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import replace
from pathlib import Path
from typing import Any, cast

import torch
from torch import nn
from torchrl.record.loggers import Logger

from kinet_rl.atomic import atomic_write_json, directory_lock
from kinet_rl.data import DatasetMismatchError, PushDataset, load_dataset
from kinet_rl.data.dataset import ALL_SPLITS
from kinet_rl.data.storage import imported_metadata
from kinet_rl.envs.geometry import SceneGeometry
from kinet_rl.evaluation.report import TrainingReport
from kinet_rl.models.checkpointing import ConfigCheckpointMixin
from kinet_rl.pipeline.capabilities import (
    check_dataset_for,
)
from kinet_rl.pipeline.datasets import collect_datasets, dataset_jobs
from kinet_rl.pipeline.settings import ExperimentSettings
from kinet_rl.rearrangement.methods import (
    check_methods,
    check_model,
    plans_every_method,
    validated_planning,
)
from kinet_rl.rearrangement.report import write_report
from kinet_rl.rearrangement.runner import run_rearrangement
from kinet_rl.rearrangement.settings import RearrangementSettings
from kinet_rl.training.checkpoint import TrainingCheckpoint
from kinet_rl.training.distributed import DistContext, init_distributed
from kinet_rl.training.loggers import MEDIA_SUFFIXES, log_media, make_logger
from kinet_rl.training.loop import Trainer

log = logging.getLogger(__name__)

#: Folder of an evaluation's finished episodes (an interrupted evaluation resumes from them).
EPISODES_DIR = "episodes"


def evaluate_rearrangement(
    model: nn.Module | None,
    settings: RearrangementSettings,
    out_dir: str | Path,
    generalization: bool = False,
    progress: bool = False,
    logger: Logger | None = None,
    step: int = 0,
) -> dict[str, Any]:
    """Runs the rearrangement evaluation and writes its report (plot, markdown, JSON, GIFs).

    With a ``logger``, the plots and GIFs also go to it, as ``rearrangement/<file stem>`` at
    ``step``. ``out_dir`` is locked meanwhile; finished episodes are kept in
    ``<out_dir>/episodes``, so that rerunning an interrupted evaluation runs only the missing ones.

    Returns:
        ``{"summary": {condition: {method: stats}}, "settings": ..., "files": [...]}``; the
        comparison's stats include ``final_distance`` (metres) and ``success_rate``.
    """
    check_methods(settings)  # bad input fails before anything is written
    check_model(settings.conditions(generalization), model)
    out_dir = Path(out_dir)
    with directory_lock(out_dir, "writing a rearrangement evaluation"):
        results = run_rearrangement(
            model, settings, generalization, progress, store_dir=out_dir / EPISODES_DIR
        )
        files = write_report(out_dir, results)
    if logger is not None:
        for path in files:
            if path.suffix in MEDIA_SUFFIXES:
                log_media(logger, f"rearrangement/{path.stem}", path, step)
    log.info("Rearrangement evaluation written to %s", out_dir)
    return {
        "summary": results.summary(),
        "settings": settings.as_dict(),
        "files": [str(f) for f in files],
    }


def held_out_sets(settings: ExperimentSettings, model: nn.Module) -> dict[str, PushDataset]:
    """The generalization sets a training run's report scores, every episode of each, by name.

    A set is scored when it shows the training scene's task, camera and image size; a set of
    another object count only for a model that handles any count (KINet, V-CDN). The others are
    skipped with a log line.
    """
    main, *extra = dataset_jobs(settings.env, settings.data)
    sets = {}
    for job in extra:
        name = job.name
        differs = job.scene_differences(main)
        if model.capabilities.any_object_count and "num_objects" in differs:
            differs.remove("num_objects")
        if differs:
            log.info("Not scoring held-out set %s: its %s differ from training's", name, differs)
            continue
        dataset = load_dataset(job.path, ALL_SPLITS)
        try:
            check_dataset_for(model, dataset)
        except DatasetMismatchError as err:
            log.info("Not scoring held-out set %s: %s", name, err)
            continue
        sets[name] = dataset
    return sets


def run_experiment(
    settings: ExperimentSettings,
    build_model: Callable[[], nn.Module],
    build_loss: Callable[[nn.Module], nn.Module],
    run_dir: str | Path,
) -> dict[str, Any]:
    """Collects the data (if missing), trains (resuming), evaluates and writes the run's report.

    Args:
        settings: The experiment.
        build_model: Builds the untrained model (called after seeding).
        build_loss: Builds the loss module of a model.
        run_dir: The run directory; re-running with the same settings resumes there.

    Returns:
        The numbers of ``results.json`` (empty on non-main processes).

    Raises:
        DirectoryInUseError: Another process is training in ``run_dir``.
    """
    run_dir = Path(run_dir)
    check_methods(settings.rearrangement)
    ctx = init_distributed(settings.device)
    with directory_lock(run_dir, "training") if ctx.is_main else nullcontext():
        return _train_and_evaluate(settings, build_model, build_loss, run_dir, ctx)


def _train_and_evaluate(
    settings: ExperimentSettings,
    build_model: Callable[[], nn.Module],
    build_loss: Callable[[nn.Module], nn.Module],
    run_dir: Path,
    ctx: DistContext,
) -> dict[str, Any]:
    """:func:`run_experiment` in its locked run directory."""
    torch.manual_seed(settings.seed + ctx.rank)
    imported = imported_metadata(settings.dataset_path)
    scene, expect = settings.scene, settings.dataset_expect
    if imported is not None:  # a robot's pushes: no simulator, no object state
        scene, expect = settings.imported_scene(imported), {"image_size": scene.image_size}
        log.info(
            "%s was imported (python -m kinet_rl.import_data), not collected: no generalization "
            "sets, no rearrangement evaluation (a robot's scene has no simulator; for data of a "
            "simulated scene, python -m kinet_rl.evaluate replays it); workspace half size %s m.",
            settings.dataset_path,
            scene.workspace_half_size,
        )
    elif ctx.is_main:
        collect_datasets(settings.env, settings.data)
    if ctx.world_size > 1:
        torch.distributed.barrier()
    data = {
        split: load_dataset(settings.dataset_path, split, expect)
        for split in ("train", "val", "test")
    }
    model = build_model()
    for dataset in data.values():
        check_dataset_for(model, dataset)
    loss = build_loss(model)
    geometry = SceneGeometry.of_scene(scene.task, scene.camera, scene.image_size)
    logger = make_logger(settings.logger, run_dir, settings.name, None, settings.wandb_kwargs)
    report = TrainingReport(
        run_dir,
        settings.name,
        model,
        data["val"],
        data["test"],
        geometry,
        settings.report.horizons,
        settings.report.num_sequences,
        logger,
        held_out_sets(settings, model) if imported is None else {},
    )
    trainer = Trainer(
        loss,
        data["train"],
        data["val"],
        settings.trainer,
        TrainingCheckpoint(run_dir, settings.identity()),
        logger,
        ctx,
        on_validate=report.on_validate,
    )
    if trainer.resume():
        log.info("Resumed %s at step %d", run_dir, trainer.step)
    trainer.fit()
    if not ctx.is_main:
        logger.close()
        return {}
    model.planning = validated_planning(model, settings.rearrangement)
    cast(ConfigCheckpointMixin, model).save_checkpoint(run_dir / model.model_file, scene=scene)
    results = {**report.final(trainer.step), "world_size": ctx.world_size}
    episodes = settings.report.rearrangement_episodes if imported is None else 0
    if plans_every_method(model.capabilities, settings.rearrangement) and episodes > 0:
        rearrangement = replace(settings.rearrangement, episodes=episodes)
        summary = evaluate_rearrangement(
            model.cpu(), rearrangement, run_dir / "rearrangement", logger=logger, step=trainer.step
        )
        results["rearrangement"] = {
            condition: {method: stats["final_distance"] for method, stats in by_method.items()}
            for condition, by_method in summary["summary"].items()
        }
    atomic_write_json(run_dir / "results.json", results)
    logger.close()  # flushes the last scalars and images
    return results
