"""Random-push data collection (TorchRL collectors), memory-mapped episode datasets, and a
robot's own pushes: the plain push folder (:class:`PushRecorder`) and its import."""

from __future__ import annotations

from kinet_rl.data.collection import collect_dataset, split_ranges
from kinet_rl.data.dataset import PushDataset, load_dataset
from kinet_rl.data.importing import (
    ImportPlan,
    ImportSettings,
    NonSquareImageError,
    import_push_folder,
    plan_import,
)
from kinet_rl.data.policy import EpisodeSeeding, RandomPushPolicy, episode_seed
from kinet_rl.data.push_folder import (
    ActionWidthError,
    FrameCountError,
    FrameSizeError,
    NonFiniteActionError,
    NotPushFolderError,
    OutsideWorkspaceError,
    PushFolderError,
    ShortEpisodeError,
    read_push_folder,
)
from kinet_rl.data.recorder import PushRecorder
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
    "ActionWidthError",
    "CorruptEpisode",
    "DatasetChecksumError",
    "DatasetCorruptError",
    "DatasetError",
    "DatasetIncompleteError",
    "DatasetMismatchError",
    "DatasetNotFoundError",
    "EpisodeSeeding",
    "FrameCountError",
    "FrameSizeError",
    "ImportPlan",
    "ImportSettings",
    "NonFiniteActionError",
    "NonSquareImageError",
    "NotPushFolderError",
    "OutsideWorkspaceError",
    "PushDataset",
    "PushFolderError",
    "PushRecorder",
    "RandomPushPolicy",
    "ShortEpisodeError",
    "VerifyReport",
    "collect_dataset",
    "episode_seed",
    "import_push_folder",
    "load_dataset",
    "plan_import",
    "read_push_folder",
    "split_ranges",
    "verify_dataset",
]
