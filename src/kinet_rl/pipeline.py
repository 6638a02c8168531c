"""The experiment pipeline as library functions: collect, train, evaluate, report.

``python -m kinet_rl.train`` and ``python -m kinet_rl.tables`` both run :func:`run_experiment`;
they turn their Hydra configs into an :class:`ExperimentSettings` (plain, typed data) and model
and loss factories, so nothing here sees a config object.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable, Mapping
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, cast

import torch
from torch import nn
from torchrl.record.loggers import Logger

from kinet_rl.atomic import atomic_write_json, directory_lock
from kinet_rl.config_schema import (
    ConfigError,
    check_arguments,
    check_keys,
    config_group,
    conform,
    parameter_annotation,
    require,
    settings_from,
    target_arguments,
)
from kinet_rl.data import (
    DatasetMismatchError,
    PushDataset,
    collect_dataset,
    load_dataset,
    split_ranges,
)
from kinet_rl.data.collection import DEFAULT_SPLITS, check_collection
from kinet_rl.data.dataset import ALL_SPLITS
from kinet_rl.envs import make_env
from kinet_rl.envs.factory import check_env_arguments
from kinet_rl.envs.geometry import SceneGeometry
from kinet_rl.envs.settings import SceneSettings
from kinet_rl.evaluation.forward import keypoint_accuracy
from kinet_rl.evaluation.report import ReportSettings, TrainingReport, hit_radius
from kinet_rl.models.checkpointing import ConfigCheckpointMixin
from kinet_rl.models.pretrained import model_card
from kinet_rl.models.world_model import KINetWorldModel
from kinet_rl.rearrangement.methods import check_methods, check_model
from kinet_rl.rearrangement.report import write_report
from kinet_rl.rearrangement.runner import run_rearrangement
from kinet_rl.rearrangement.settings import RearrangementSettings
from kinet_rl.training.checkpoint import TrainingCheckpoint
from kinet_rl.training.distributed import DistContext, init_distributed
from kinet_rl.training.loggers import LOGGER_KINDS, MEDIA_SUFFIXES, log_media, make_logger
from kinet_rl.training.loop import Trainer, TrainerSettings

log = logging.getLogger(__name__)

#: Env settings a dataset must match to train a model of the experiment.
DATASET_ENV_KEYS = ("task", "camera", "image_size", "num_objects")
#: File name of a trained model in its run directory.
KINET_FILE, BASELINE_FILE = "kinet.pt", "model.pt"
#: Top-level keys of the root config (``conf/config.yaml``); ``checkpoint`` is read by
#: ``kinet_rl.evaluate``, ``estimate`` by ``kinet_rl.train``; ``keypoints`` is interpolated by the
#: keypoint models' configs (``conf/model/kinet.yaml``, ``vcdn.yaml``).
ROOT_KEYS = (
    "exp_name",
    "seed",
    "keypoints",
    "device",
    "estimate",
    "checkpoint",
    "env",
    "data",
    "model",
    "loss",
    "trainer",
    "report",
    "logger",
    "eval",
)
#: The loss constructor's argument that gets the model (the entry points pass it, not the config).
LOSS_MODEL_ARGUMENT = "world_model"
#: Keys of a ``data.generalization`` entry.
GENERALIZATION_KEYS = ("num_episodes", "env", "seed")
#: Splits that training and its report read.
TRAINING_SPLITS = ("train", "val", "test")
#: Folder of an evaluation's finished episodes (an interrupted evaluation resumes from them).
EPISODES_DIR = "episodes"


@dataclass(frozen=True)
class ExperimentSettings:
    """Everything one experiment runs with, as plain data.

    Attributes:
        name: Experiment name (report title, logger run name).
        seed: Seed of model initialisation (each process adds its rank).
        device: ``"auto"``, ``"cpu"`` or ``"cuda"``.
        env: Arguments of :func:`kinet_rl.envs.make_env` (the ``env`` group, no ``_target_``).
        data: Arguments of :func:`kinet_rl.data.collect_dataset` plus ``generalization``
            (extra datasets: name -> ``num_episodes``, ``env`` overrides, optional ``seed``).
        trainer: Training settings.
        report: Final-evaluation settings.
        rearrangement: Settings of the rearrangement evaluation.
        logger: TorchRL logger kind (``csv``, ``tensorboard``, ``wandb``).
        wandb_kwargs: Extra arguments of the W&B logger.
        model_config: The model's config, part of the run identity that resuming checks.
        loss_config: The loss's config, likewise.
        estimate: Measure this machine's speed and log a time estimate before any work
            (:mod:`kinet_rl.estimate`; False logs the plan alone).
    """

    name: str
    seed: int
    device: str
    env: Mapping[str, Any]
    data: Mapping[str, Any]
    trainer: TrainerSettings
    report: ReportSettings
    rearrangement: RearrangementSettings
    logger: str = "csv"
    wandb_kwargs: Mapping[str, Any] = field(default_factory=dict)
    model_config: Mapping[str, Any] = field(default_factory=dict)
    loss_config: Mapping[str, Any] = field(default_factory=dict)
    estimate: bool = True

    def __post_init__(self) -> None:
        require(self.logger in LOGGER_KINDS, "logger.kind", self.logger, f"one of {LOGGER_KINDS}")
        require(
            self.device == "auto" or _is_device(self.device),
            "device",
            self.device,
            "auto or a torch device (cpu, cuda, cuda:1)",
        )
        self._check_episode_length()
        self._check_splits()
        loss = self.loss_config
        if (
            loss.get("ctr_negatives") == "episode"
            and loss.get("ctr_weight", 0) > 0
            and self.trainer.steps_per_episode < 2
        ):
            raise ValueError(
                "loss.ctr_negatives=episode takes its negatives from other steps of the same "
                f"episode, but trainer.steps_per_episode={self.trainer.steps_per_episode} samples "
                "one step per episode (the contrastive loss would be 0); set "
                "trainer.steps_per_episode=4 (or another divisor of the batch size) or "
                "loss.ctr_negatives=batch."
            )
        if loss.get("rollout_weight", 0) > 0 and self.trainer.horizon < 2:
            raise ValueError(
                "loss.rollout_weight > 0 trains on the pushes after each transition, but "
                f"trainer.horizon={self.trainer.horizon}; set trainer.horizon=3 (or more) or "
                "loss.rollout_weight=0."
            )

    def _check_episode_length(self) -> None:
        """Training windows and report horizons must fit in an episode (``env.max_steps``)."""
        length = self.env.get("max_steps")
        if length is None:
            return
        trainer, horizons = self.trainer, self.report.horizons
        fits = f"at most env.max_steps={length} (the pushes per episode)"
        require(trainer.horizon <= length, "trainer.horizon", trainer.horizon, fits)
        require(max(horizons) <= length, "report.horizons", list(horizons), f"values {fits}")
        windows = length - trainer.horizon + 1
        require(
            trainer.steps_per_episode <= windows,
            "trainer.steps_per_episode",
            trainer.steps_per_episode,
            f"at most env.max_steps - trainer.horizon + 1 = {windows}",
        )

    def _check_splits(self) -> None:
        """Each split that training reads gets at least one episode of the main dataset."""
        splits = self.data.get("splits") or DEFAULT_SPLITS
        with config_group("data"):
            ranges = split_ranges(self.data["num_episodes"], splits)
        sizes = {name: stop - start for name, (start, stop) in ranges.items()}
        empty = [name for name in TRAINING_SPLITS if sizes.get(name, 0) < 1]
        require(
            not empty,
            "data.splits",
            dict(splits),
            f"fractions that give {', '.join(TRAINING_SPLITS)} at least one of the "
            f"data.num_episodes={self.data['num_episodes']} episodes each (empty: {empty})",
        )

    @classmethod
    def from_container(cls, cfg: Mapping[str, Any]) -> ExperimentSettings:
        """Settings from a resolved plain-container config (``conf/config.yaml``'s layout).

        Checks the keys, types and ranges of every group (``env``, ``data``, ``trainer``,
        ``report``, ``eval``, ``logger``; ``model`` and ``loss`` against their ``_target_``'s
        parameters, whose ranges :func:`check_config` checks by building them).

        Raises:
            ConfigError: An unknown key, a wrong type or an out-of-range value, named.
        """
        check_keys(cfg, ROOT_KEYS)
        conform("checkpoint", cfg.get("checkpoint"), str | None)  # read by kinet_rl.evaluate
        with config_group("env"):
            check_env_arguments(cfg["env"])
        env = {k: v for k, v in cfg["env"].items() if k != "_target_"}
        logger = dict(cfg["logger"])
        check_keys(logger, ("kind", "wandb_kwargs"), "logger")
        with config_group("eval"):
            rearrangement = RearrangementSettings.from_dicts(cfg.get("eval") or {}, env)
        model_config, loss_config = dict(cfg["model"]), dict(cfg["loss"])
        target_arguments(model_config, "model")
        target_arguments(loss_config, "loss", exclude=[LOSS_MODEL_ARGUMENT])
        return cls(
            name=conform("exp_name", cfg["exp_name"], str),
            seed=conform("seed", cfg["seed"], int),
            device=conform("device", cfg["device"], str),
            env=env,
            data=check_data(cfg["data"], env),
            trainer=settings_from(TrainerSettings, cfg["trainer"], "trainer"),
            report=settings_from(ReportSettings, cfg["report"], "report"),
            rearrangement=rearrangement,
            logger=conform("logger.kind", logger["kind"], str),
            wandb_kwargs=conform(
                "logger.wandb_kwargs", logger.get("wandb_kwargs") or {}, Mapping[str, Any]
            ),
            model_config=model_config,
            loss_config=loss_config,
            estimate=conform("estimate", cfg.get("estimate", True), bool),
        )

    @property
    def scene(self) -> SceneSettings:
        """The experiment's scene."""
        return SceneSettings.from_mapping(self.env)

    @property
    def dataset_path(self) -> Path:
        """Folder of the experiment's main dataset."""
        return dataset_path(self.data)

    @property
    def dataset_expect(self) -> dict[str, Any]:
        """What the main dataset must record (``load_dataset``'s ``expect``): the scene's
        :data:`DATASET_ENV_KEYS` and ``data.num_objects_range``, whose ``high`` is then the
        dataset's ``num_objects``."""
        expect = {k: self.env[k] for k in DATASET_ENV_KEYS}
        count_range = self.data.get("num_objects_range")
        if count_range is None:
            return {**expect, "num_objects_range": None}
        return {**expect, "num_objects": count_range[1], "num_objects_range": list(count_range)}

    def identity(self) -> dict[str, Any]:
        """The settings a checkpoint must share with the run that resumes it."""
        return {
            "model": dict(self.model_config),
            "loss": dict(self.loss_config),
            "dataset": str(self.dataset_path),
            "batch_size": self.trainer.batch_size,
        }


def _is_device(name: str) -> bool:
    try:
        torch.device(name)
    except RuntimeError:
        return False
    return True


def check_data(data: Mapping[str, Any], env: Mapping[str, Any]) -> dict[str, Any]:
    """The ``data`` group, checked: :func:`collect_dataset` arguments plus ``generalization``.

    Each generalization set may set ``num_episodes``, ``seed`` and ``env`` overrides, which must
    give a valid scene together with ``env``.

    Raises:
        ConfigError: An unknown key, a wrong type or an out-of-range value, named.
    """
    main = {k: v for k, v in data.items() if k != "generalization"}
    args = check_arguments(collect_dataset, main, "data", exclude=("env_fn", "env_config"))
    with config_group("data"):
        check_collection(
            args["num_episodes"],
            args["num_workers"],
            args["chunk_episodes"],
            DEFAULT_SPLITS if args["splits"] is None else args["splits"],
            args["policy"] or {},
            args["max_discard_fraction"],
            args["backend"],
            args["distributed"],
            args["num_objects_range"],
        )
    sets = conform(
        "data.generalization", data.get("generalization"), Mapping[str, Mapping[str, Any]] | None
    )
    for name, extra in (sets or {}).items():
        group = f"data.generalization.{name}"
        check_keys(extra, GENERALIZATION_KEYS, group)
        size = extra.get("num_episodes", args["num_episodes"])  # the main set's by default
        num_episodes = conform(f"{group}.num_episodes", size, int)
        require(
            num_episodes >= 1, f"{group}.num_episodes", num_episodes, "an integer of at least 1"
        )
        conform(f"{group}.seed", extra.get("seed"), int | None)
        overrides = conform(f"{group}.env", extra.get("env") or {}, Mapping[str, Any])
        with config_group(f"{group}.env"):
            check_env_arguments({**env, **overrides})
    return dict(data)


def check_config(cfg: Mapping[str, Any]) -> ExperimentSettings:
    """Checks a whole resolved root config before any work; returns its settings.

    Builds the typed settings of every group (:meth:`ExperimentSettings.from_container`), checks
    the rearrangement methods, then builds the model and its loss once on the CPU (and drops
    them) so that their constructors' own checks run too. Entry points call it first: a typo
    fails in seconds, not after an hour of collection.

    Raises:
        ConfigError: The first invalid entry, named with its value and what is allowed.
    """
    settings = ExperimentSettings.from_container(cfg)
    with config_group("eval"):
        check_methods(settings.rearrangement)
    model_class, model_args = target_arguments(settings.model_config, "model")
    loss_class, loss_args = target_arguments(
        settings.loss_config, "loss", exclude=[LOSS_MODEL_ARGUMENT]
    )
    with config_group("model"):
        model = model_class(**model_args)
    count_range = settings.data.get("num_objects_range")
    if count_range is not None and not trains_on_variable_object_counts(model):
        raise ConfigError(
            "data.num_objects_range",
            f"{list(count_range)} collects episodes of different object counts, but "
            f"{type(model).__name__} learns from every object's ground-truth position and "
            "needs one count per dataset. Set data.num_objects_range=null (one count, "
            "env.num_objects), or train a keypoint model on the range (model=kinet loss=kinet).",
        )
    trains = parameter_annotation(loss_class, LOSS_MODEL_ARGUMENT)
    if isinstance(trains, type) and not isinstance(model, trains):
        raise ConfigError(
            "loss",
            f"{loss_class.__name__} trains a {trains.__name__}, but the model group builds a "
            f"{type(model).__name__}; choose the loss group of the model (e.g. model=forw "
            "loss=forw).",
        )
    with config_group("loss"):
        loss_class(**{LOSS_MODEL_ARGUMENT: model}, **loss_args)
    return settings


def dataset_path(data: Mapping[str, Any]) -> Path:
    """Folder of the main dataset of a ``data`` group: ``<root>/<name>``."""
    return Path(data["root"]) / data["name"]


@dataclass(frozen=True)
class DatasetJob:
    """One dataset an experiment collects.

    Attributes:
        arguments: Keyword arguments of :func:`collect_dataset` (without ``env_fn`` and
            ``env_config``).
        env: Arguments of :func:`make_env` for its episodes.
    """

    arguments: Mapping[str, Any]
    env: Mapping[str, Any]

    @property
    def path(self) -> Path:
        """The dataset's folder."""
        return dataset_path(self.arguments)

    def collect(self) -> Path:
        """Collects the dataset (skipped when complete, resumed when partial); returns its folder."""
        env_fn = functools.partial(make_env, **self.env)
        return collect_dataset(env_fn=env_fn, env_config=dict(self.env), **self.arguments)


def dataset_jobs(env: Mapping[str, Any], data: Mapping[str, Any]) -> list[DatasetJob]:
    """The main dataset of ``data``, then each of its generalization sets, in collection order.

    Generalization set ``i`` (1-based, in order) uses seed ``data.seed + i`` unless it sets its
    own; its ``env`` entry overrides the env settings. Generalization sets hold one object
    count (``env.num_objects``) even when the main set has a ``num_objects_range``.
    """
    main = dict(data)
    generalization = main.pop("generalization", None) or {}
    jobs = [DatasetJob(main, dict(env))]
    one_count = {"num_objects_range": None} if "num_objects_range" in main else {}
    for offset, (name, extra) in enumerate(generalization.items(), start=1):
        extra = dict(extra)
        env_overrides = extra.pop("env", None) or {}
        arguments = {**main, **one_count, "seed": main["seed"] + offset, **extra, "name": name}
        jobs.append(DatasetJob(arguments, {**env, **env_overrides}))
    return jobs


def collect_datasets(env: Mapping[str, Any], data: Mapping[str, Any]) -> list[Path]:
    """Collects every dataset of :func:`dataset_jobs`: complete ones are skipped, partial ones
    resumed."""
    return [job.collect() for job in dataset_jobs(env, data)]


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


def trained_model_file(model_class: type) -> str:
    """The file name of a trained model of ``model_class`` in its run directory."""
    return KINET_FILE if issubclass(model_class, KINetWorldModel) else BASELINE_FILE


def model_file(model: nn.Module) -> str:
    """The file name of a trained model in its run directory."""
    return trained_model_file(type(model))


def trains_on_variable_object_counts(model: nn.Module) -> bool:
    """Whether ``model`` declares ``variable_object_count`` (keypoint models do): it trains on
    datasets whose episodes hold different object counts, with NaN for the missing objects."""
    return bool(getattr(model, "variable_object_count", False))


def check_dataset_for(model: nn.Module, dataset: PushDataset) -> None:
    """Raises ``DatasetMismatchError`` if ``dataset`` stores no array that ``model`` reads, or
    episodes of different object counts that ``model`` cannot train on.

    A model lists the arrays in ``state_keys`` (IN-full: ``object_yaw``, ``object_shape``;
    datasets collected by an older kinet_rl lack ``object_shape``).
    """
    dataset.check_keys(getattr(model, "state_keys", ()), type(model).__name__)
    if not trains_on_variable_object_counts(model):
        dataset.check_fixed_object_count(type(model).__name__)


def held_out_sets(settings: ExperimentSettings, model: nn.Module) -> dict[str, PushDataset]:
    """The generalization sets a training run's report scores, every episode of each, by name.

    A set is scored when it shows the training scene's task, camera and image size; a set of
    another object count only for a model that handles any count (KINet, V-CDN). The others are
    skipped with a log line.
    """
    main, *extra = dataset_jobs(settings.env, settings.data)
    sets = {}
    for job in extra:
        name = job.arguments["name"]
        differs = [k for k in DATASET_ENV_KEYS if job.env[k] != main.env[k]]
        if trains_on_variable_object_counts(model) and "num_objects" in differs:
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
    if ctx.is_main:
        collect_datasets(settings.env, settings.data)
    if ctx.world_size > 1:
        torch.distributed.barrier()
    data = {
        split: load_dataset(settings.dataset_path, split, settings.dataset_expect)
        for split in ("train", "val", "test")
    }
    model = build_model()
    for dataset in data.values():
        check_dataset_for(model, dataset)
    loss = build_loss(model)
    scene = settings.scene
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
        held_out_sets(settings, model),
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
    cast(ConfigCheckpointMixin, model).save_checkpoint(run_dir / model_file(model), scene=scene)
    results = {**report.final(trainer.step), "world_size": ctx.world_size}
    episodes = settings.report.rearrangement_episodes
    if isinstance(model, KINetWorldModel) and episodes > 0:
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


def pretrained_keypoint_accuracy(name: str, work_dir: Path) -> float:
    """Keypoint accuracy of shipped model ``name`` on episodes collected afresh into ``work_dir``.

    Follows the ``check`` protocol of its model card (:func:`kinet_rl.models.model_card`): that
    many random-push episodes of the card's scene and seed, every frame of them scored with the
    training report's hit radius. The card's ``check.keypoint_accuracy`` was measured this way.
    """
    card = model_card(name)
    check, scene = card["check"], SceneSettings.from_mapping(card["scene"])
    env_config = {**scene.as_dict(), "max_steps": check["pushes_per_episode"]}
    path = collect_dataset(
        functools.partial(make_env, **env_config),
        env_config,
        root=work_dir,
        name=f"check_{name}",
        num_episodes=check["episodes"],
        seed=check["seed"],
        num_workers=1,
        splits={"train": 1.0},
        progress=False,
    )
    geometry = SceneGeometry.of_scene(scene.task, scene.camera, scene.image_size)
    return keypoint_accuracy(
        KINetWorldModel.from_pretrained(name),
        load_dataset(path, "train"),
        geometry,
        hit_radius(scene.image_size),
        num_frames=check["frames"],
        seed=check["seed"],
    )
