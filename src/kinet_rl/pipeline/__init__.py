"""The experiment pipeline as library functions: collect, train, evaluate, report.

``python -m kinet_rl.train`` and ``python -m kinet_rl.tables`` both run :func:`run_experiment`;
they turn their Hydra configs into an :class:`ExperimentSettings` (plain, typed data) and model
and loss factories, so nothing here sees a config object.

Dependency order inside the package: ``capabilities`` (a trained model's file, the datasets it
can train on) and ``datasets`` (what an experiment collects) <- ``settings`` (the typed settings
and the whole config's check) <- ``experiment`` (collect, train, evaluate, report);
``pretrained`` (a shipped model's card check) stands alone.
"""

from __future__ import annotations

from kinet_rl.pipeline.capabilities import (
    check_dataset_for,
)
from kinet_rl.pipeline.datasets import DatasetJob, collect_datasets, dataset_jobs, dataset_path
from kinet_rl.pipeline.experiment import evaluate_rearrangement, held_out_sets, run_experiment
from kinet_rl.pipeline.pretrained import (
    CHECK_PROTOCOL,
    fresh_keypoint_accuracy,
    pretrained_keypoint_accuracy,
)
from kinet_rl.pipeline.settings import ExperimentSettings, check_config, check_data

__all__ = [
    "DatasetJob",
    "ExperimentSettings",
    "check_config",
    "check_data",
    "check_dataset_for",
    "collect_datasets",
    "dataset_jobs",
    "dataset_path",
    "evaluate_rearrangement",
    "held_out_sets",
    "pretrained_keypoint_accuracy",
    "fresh_keypoint_accuracy",
    "CHECK_PROTOCOL",
    "run_experiment",
]
