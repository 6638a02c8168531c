"""The datasets of an experiment: the main one and its generalization sets, in collection
order (:func:`dataset_jobs`), and their collection (:func:`collect_datasets`)."""

from __future__ import annotations

import functools
import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from kinet_rl.atomic import DirectoryInUseError, wait_for_directory
from kinet_rl.data import collect_dataset
from kinet_rl.envs import make_env

#: Env settings a dataset must match to train a model of the experiment.
DATASET_ENV_KEYS = ("task", "camera", "image_size", "num_objects")

log = logging.getLogger(__name__)


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

    @property
    def name(self) -> str:
        """The dataset's name (its folder under ``data.root``)."""
        return self.arguments["name"]

    @property
    def num_episodes(self) -> int:
        """Episodes of the finished dataset."""
        return self.arguments["num_episodes"]

    @property
    def num_workers(self) -> int:
        """Collection workers."""
        return self.arguments["num_workers"]

    @property
    def seed(self) -> int:
        """Seed of its first episode."""
        return self.arguments["seed"]

    @property
    def policy(self) -> Mapping[str, Any]:
        """Arguments of its random-push policy (:class:`~kinet_rl.data.RandomPushPolicy`)."""
        return self.arguments["policy"] or {}

    @property
    def pushes_per_episode(self) -> int:
        """Pushes of each episode (``env.max_steps``)."""
        return self.env["max_steps"]

    def scene_differences(self, other: DatasetJob) -> list[str]:
        """The :data:`DATASET_ENV_KEYS` whose env settings differ from ``other``'s."""
        return [k for k in DATASET_ENV_KEYS if self.env[k] != other.env[k]]

    def collect(self) -> Path:
        """Collects the dataset (skipped when complete, resumed when partial); returns its folder.

        When another process is collecting it (a sweep's jobs that share a dataset), this one
        waits for it, then finds the dataset complete (or resumes what it left).
        """
        env_fn = functools.partial(make_env, **self.env)
        while True:
            try:
                return collect_dataset(env_fn=env_fn, env_config=dict(self.env), **self.arguments)
            except DirectoryInUseError as busy:
                log.info("%s Waiting for it.", busy)
                wait_for_directory(self.path)


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
