"""An experiment's typed settings (:class:`ExperimentSettings`) and the check of a whole root
config (:func:`check_config`), which entry points run before any collection or training."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import torch

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
from kinet_rl.data import collect_dataset, split_ranges
from kinet_rl.data.collection import DEFAULT_SPLITS, check_collection
from kinet_rl.data.storage import IMPORT_RECORD
from kinet_rl.envs.factory import check_env_arguments
from kinet_rl.envs.settings import SceneSettings
from kinet_rl.evaluation.report import ReportSettings
from kinet_rl.pipeline.datasets import DATASET_ENV_KEYS, DatasetJob, dataset_jobs, dataset_path
from kinet_rl.rearrangement.methods import check_methods
from kinet_rl.rearrangement.settings import RearrangementSettings
from kinet_rl.training.loggers import LOGGER_KINDS
from kinet_rl.training.loop import TrainerSettings

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
        self._check_windows(
            length, f"env.max_steps={length} (the pushes per episode)", "env.max_steps"
        )

    def _check_windows(self, length: int, limit: str, name: str) -> None:
        """Training windows and report horizons must fit in episodes of ``length`` pushes
        (``limit``: that length in words; ``name``: its name)."""
        trainer, horizons = self.trainer, self.report.horizons
        fits = f"at most {limit}"
        require(trainer.horizon <= length, "trainer.horizon", trainer.horizon, fits)
        require(max(horizons) <= length, "report.horizons", list(horizons), f"values {fits}")
        windows = length - trainer.horizon + 1
        require(
            trainer.steps_per_episode <= windows,
            "trainer.steps_per_episode",
            trainer.steps_per_episode,
            f"at most {name} - trainer.horizon + 1 = {windows}",
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
    def main_dataset(self) -> DatasetJob:
        """The experiment's main dataset (the first of :func:`dataset_jobs`)."""
        return dataset_jobs(self.env, self.data)[0]

    @property
    def model_name(self) -> str:
        """The last part of the model's ``_target_`` (e.g. ``KINetWorldModel``)."""
        return self.model_config["_target_"].rsplit(".", 1)[-1]

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

    def imported_scene(self, metadata: Mapping[str, Any]) -> SceneSettings:
        """The scene of a run on an imported dataset (a robot's pushes, its ``metadata``): the
        experiment's, with the dataset's workspace half size, which a checkpoint keeps for
        planning in the robot's units.

        Raises:
            ConfigError: ``env.image_size`` is not the dataset's, or the training windows or the
                report's horizons are longer than its episodes.
        """
        path, size = self.dataset_path, metadata["image_size"]
        require(
            self.env["image_size"] == size,
            "env.image_size",
            self.env["image_size"],
            f"{size}, the image size of the imported dataset {path} (set env.image_size={size})",
        )
        length = metadata["episode_length"]
        limit = f"{length}, the pushes per episode of the imported dataset {path}"
        self._check_windows(length, limit, "the imported episodes' pushes")
        record = metadata.get(IMPORT_RECORD, {})
        box, source = record.get("settings", {}).get("crop_box"), record.get("source_image_size")
        return replace(
            self.scene,
            workspace_half_size=float(metadata["workspace_half_size"]),
            crop_box=None if box is None else tuple(box),
            source_image_size=None if source is None else tuple(source),
        )

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
    if count_range is not None and not model.capabilities.any_object_count:
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
