"""Random-push data collection (TorchRL collectors) and memory-mapped episode datasets."""

from __future__ import annotations

from kinet_rl.data.collection import collect_dataset, split_ranges
from kinet_rl.data.dataset import PushDataset, load_dataset
from kinet_rl.data.policy import EpisodeSeeding, RandomPushPolicy, episode_seed
from kinet_rl.data.storage import (
    DatasetChecksumError,
    DatasetCorruptError,
    DatasetError,
    DatasetIncompleteError,
    DatasetMismatchError,
    DatasetNotFoundError,
)
from kinet_rl.data.verification import CorruptEpisode, VerifyReport, verify_dataset

__all__ = [
    "CorruptEpisode",
    "DatasetChecksumError",
    "DatasetCorruptError",
    "DatasetError",
    "DatasetIncompleteError",
    "DatasetMismatchError",
    "DatasetNotFoundError",
    "EpisodeSeeding",
    "PushDataset",
    "RandomPushPolicy",
    "VerifyReport",
    "collect_dataset",
    "episode_seed",
    "load_dataset",
    "split_ranges",
    "verify_dataset",
]
