"""Importing a robot's pushes (a plain push folder, :mod:`kinet_rl.data.push_folder`) into
kinet_rl's episode storage, as a dataset of pixels and pushes without object state.

:func:`plan_import` checks the whole folder and the settings before anything is written and
says what the import will do (:meth:`ImportPlan.describe`): the frames are centre-cropped (or
cropped to a given square) and resized to the square training size, the pushes divided by the
workspace half size, the episodes cut into windows of ``episode_length`` pushes (default: the
shortest episode's pushes; the pushes left over at an episode's end are not used) and split by
episode into train / val / test like collection does. :func:`import_push_folder` writes them
with the collection's :class:`~kinet_rl.data.storage.EpisodeWriter` (atomic chunks, per-episode
SHA-256 checksums, resumable: rerun the same import after an interruption).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from PIL import Image
from tensordict import TensorDict
from tqdm import tqdm

from kinet_rl.atomic import directory_lock
from kinet_rl.config_schema import require
from kinet_rl.data.collection import DEFAULT_SPLITS, package_versions, split_ranges
from kinet_rl.data.push_folder import PushFolder, PushFolderError, read_push_folder
from kinet_rl.data.storage import (
    FORMAT_VERSION,
    IMPORT_RECORD,
    METADATA_FILE,
    DatasetMismatchError,
    EpisodeWriter,
    imported_metadata,
)
from kinet_rl.envs.frames import resize_filter, square_frame
from kinet_rl.envs.settings import check_image_size
from kinet_rl.keys import ACTION, PIXELS

logger = logging.getLogger(__name__)

#: ``crop`` value that takes the largest centred square of each frame.
CENTRE_CROP = "center"
IMPORT_HINT = "python -m kinet_rl.import_data <push folder> --root <root> --name <name>"


class NonSquareImageError(PushFolderError):
    """The frames are not square and no crop was given to make them so."""


@dataclass(frozen=True)
class ImportSettings:
    """How a push folder becomes a training dataset.

    Attributes:
        image_size: Side of the square training images, pixels (a multiple of 4, >= 16).
        crop: ``"center"`` (the largest centred square), ``(left, top, size)`` (a square box in
            source pixels), or None (the frames must be square already).
        episode_length: Pushes per stored episode (None: the shortest episode's); longer
            episodes are cut into consecutive windows of this many pushes.
        splits: Fractions of the source episodes per split, assigned as contiguous ranges.
        chunk_episodes: Stored episodes written per commit (the most a killed import redoes).
    """

    image_size: int = 64
    crop: str | tuple[int, int, int] | None = None
    episode_length: int | None = None
    splits: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_SPLITS))
    chunk_episodes: int = 16

    def __post_init__(self) -> None:
        check_image_size(self.image_size)
        crop = self.crop
        require(
            crop is None
            or crop == CENTRE_CROP
            or (
                isinstance(crop, tuple)
                and len(crop) == 3
                and all(isinstance(v, int) for v in crop)
                and min(crop[:2]) >= 0
                and crop[2] >= 1
            ),
            "crop",
            crop,
            f"{CENTRE_CROP!r}, (left, top, size) in pixels, or None for square frames",
        )
        require(
            self.episode_length is None or self.episode_length >= 1,
            "episode_length",
            self.episode_length,
            "None (the shortest episode's pushes) or an integer of at least 1",
        )
        require(self.chunk_episodes >= 1, "chunk_episodes", self.chunk_episodes, "at least 1")
        split_ranges(1, self.splits)  # fractions of at least 0 that sum to 1


def crop_box(width: int, height: int, crop: str | tuple[int, int, int] | None) -> tuple[int, ...]:
    """The square ``(left, top, size)`` of ``width`` x ``height`` frames that ``crop`` keeps.

    Raises:
        NonSquareImageError: The frames are not square and ``crop`` is None.
        ConfigError: The box does not fit in the frames.
    """
    if crop is None:
        if width != height:
            raise NonSquareImageError(
                f"The frames are {width}x{height} px, not square, and no crop was given. Pass "
                f"--crop {CENTRE_CROP} (the centred {min(width, height)}x{min(width, height)} "
                "px square) or --crop LEFT,TOP,SIZE (a square box in pixels)."
            )
        return (0, 0, width)
    if isinstance(crop, str):  # CENTRE_CROP, checked by ImportSettings
        size = min(width, height)
        return ((width - size) // 2, (height - size) // 2, size)
    left, top, size = crop
    require(
        left + size <= width and top + size <= height,
        "crop",
        list(crop),
        f"a square box inside the {width}x{height} px frames",
    )
    return (left, top, size)


@dataclass(frozen=True)
class ImportPlan:
    """What an import will write, checked: see :func:`plan_import`.

    Attributes:
        folder: The checked push folder.
        settings: The import settings.
        box: ``(left, top, size)`` of the square kept from each frame.
        episode_length: Pushes per stored episode T.
        windows: ``(source episode, first push)`` of each stored episode, in order.
        splits: Stored-episode ranges ``[start, stop)`` per split (by source episode).
    """

    folder: PushFolder
    settings: ImportSettings
    box: tuple[int, ...]
    episode_length: int
    windows: tuple[tuple[int, int], ...]
    splits: dict[str, list[int]]

    @property
    def image_size(self) -> int:
        """Side of the stored square images, pixels."""
        return self.settings.image_size

    @property
    def num_episodes(self) -> int:
        """Stored episodes (windows)."""
        return len(self.windows)

    @property
    def unused_pushes(self) -> int:
        """Pushes left over at the episodes' ends (shorter than a window)."""
        total = sum(len(episode.pushes) for episode in self.folder.episodes)
        return total - self.num_episodes * self.episode_length

    @property
    def resample(self) -> Image.Resampling:
        """The resize filter: box (area average) when shrinking, bicubic when enlarging."""
        return resize_filter(self.box[2], self.settings.image_size)

    def describe(self, path: Path | None = None) -> str:
        """What the import does, in a few lines (the command prints it before starting)."""
        folder, meta, (left, top, size) = self.folder, self.folder.meta, self.box
        width, height = folder.image_size
        frames = sorted({len(e.frames) for e in folder.episodes})
        counts = f"{frames[0]}" if len(frames) == 1 else f"{frames[0]}-{frames[-1]}"
        camera = f", camera {meta.camera!r}" if meta.camera else ""
        kept = "the whole frame" if (size, size) == (width, height) else f"crop {size}x{size} px"
        where = f" at (left {left}, top {top})" if kept != "the whole frame" else ""
        target = self.settings.image_size
        splits = ", ".join(f"{name} {stop - start}" for name, (start, stop) in self.splits.items())
        lines = [
            f"Importing {folder.root}: {len(folder.episodes)} episodes of {counts} frames, "
            f"{width}x{height} px{camera}; workspace half size {meta.workspace_half_size} m "
            f"(pushes in {meta.units})",
            f"  frames: {kept}{where}, resized to {target}x{target} px "
            f"({self.resample.name.lower()} filter)",
            f"  stored episodes of {self.episode_length} pushes: {self.num_episodes} "
            f"({self.unused_pushes} pushes at episode ends unused)",
            f"  splits by source episode: {splits} stored episodes",
        ]
        if path is not None:
            lines.append(f"  into {path}")
        return "\n".join(lines)

    def writer_settings(self) -> dict[str, Any]:
        """What a resumed import must share with the interrupted one (:class:`EpisodeWriter`)."""
        return {
            "imported_from": str(self.folder.root.resolve()),
            "fingerprint": self.folder.fingerprint(),
            "image_size": self.settings.image_size,
            "crop_box": list(self.box),
            "episode_length": self.episode_length,
            "splits": dict(self.settings.splits),
        }

    def episode(self, index: int) -> TensorDict:
        """Stored episode ``index``: ``pixels`` uint8 ``[T + 1, S, S, 3]``, ``action`` ``[T, 4]``
        and ``source_episode``."""
        source, first = self.windows[index]
        episode, length = self.folder.episodes[source], self.episode_length
        frames = [
            np.asarray(square_frame(image, self.box, self.settings.image_size))
            for image in episode.load_frames(first, first + length + 1)
        ]
        return TensorDict(
            {
                PIXELS: torch.from_numpy(np.stack(frames)),
                ACTION: torch.from_numpy(episode.pushes[first : first + length].copy()),
                "source_episode": torch.tensor(source, dtype=torch.int64),
            }
        )


def plan_import(
    source: str | Path | PushFolder, settings: ImportSettings | None = None
) -> ImportPlan:
    """Checks a push folder and the import settings; writes nothing.

    ``source`` is a push folder's path or an already checked :class:`PushFolder` (e.g. a
    LeRobot dataset's, :meth:`kinet_rl.data.lerobot.LeRobotSource.as_push_folder`).

    Raises:
        PushFolderError: The folder is not in the format or holds bad data (a named subclass:
            ``NotPushFolderError``, ``ActionWidthError``, ``NonFiniteActionError``,
            ``ShortEpisodeError``, ``FrameCountError``, ``FrameSizeError``,
            ``OutsideWorkspaceError``, :class:`NonSquareImageError`).
        ConfigError: A setting out of range (e.g. a crop box outside the frames, an episode
            length no episode reaches).
    """
    settings = settings or ImportSettings()
    folder = source if isinstance(source, PushFolder) else read_push_folder(source)
    box = crop_box(*folder.image_size, settings.crop)
    pushes = [len(episode.pushes) for episode in folder.episodes]
    length = settings.episode_length or min(pushes)
    require(
        length <= max(pushes),
        "episode_length",
        length,
        f"at most the longest episode's {max(pushes)} pushes",
    )
    windows: list[tuple[int, int]] = []
    first_window: list[int] = []
    for index, count in enumerate(pushes):
        first_window.append(len(windows))
        windows += [(index, start) for start in range(0, count - length + 1, length)]
    first_window.append(len(windows))
    splits = {
        name: [first_window[start], first_window[stop]]
        for name, (start, stop) in split_ranges(len(pushes), settings.splits).items()
    }
    return ImportPlan(folder, settings, box, length, tuple(windows), splits)


def import_push_folder(
    plan: ImportPlan, root: str | Path, name: str, progress: bool = True
) -> Path:
    """Writes the dataset ``<root>/<name>`` of an :func:`plan_import` plan; resumes a partial one.

    Returns:
        The dataset folder (loadable with :func:`~kinet_rl.data.load_dataset`).

    Raises:
        DatasetMismatchError: ``<root>/<name>`` holds another dataset (complete or partial).
        DirectoryInUseError: Another process writes there.
    """
    path = Path(root) / name
    settings = plan.writer_settings()
    with directory_lock(path, "importing a dataset"):
        if (path / METADATA_FILE).exists():
            done = imported_metadata(path)
            if done is None or done[IMPORT_RECORD].get("settings") != settings:
                raise DatasetMismatchError(
                    f"{path} already holds another dataset; import into another --name, or "
                    f"delete {path} first."
                )
            logger.info("Dataset %s is already imported; nothing to do.", path)
            return path
        size = plan.settings.image_size
        writer = EpisodeWriter(path, plan.num_episodes, plan.episode_length, size, None, settings)
        chunk = plan.settings.chunk_episodes
        start_time = time.perf_counter()
        with tqdm(
            total=plan.num_episodes, initial=writer.committed, desc=name, disable=not progress
        ) as bar:
            for start in range(writer.committed, plan.num_episodes, chunk):
                stop = min(start + chunk, plan.num_episodes)
                writer.commit(torch.stack([plan.episode(i) for i in range(start, stop)]), stop, 0)
                bar.update(stop - start)
        meta = plan.folder.meta
        writer.finalize(
            {
                "format_version": FORMAT_VERSION,
                "complete": True,
                "name": name,
                "env": {},
                "num_episodes": plan.num_episodes,
                "episode_length": plan.episode_length,
                "image_size": size,
                "num_objects": None,
                "workspace_half_size": meta.workspace_half_size,
                "splits": plan.splits,
                "split_fractions": dict(plan.settings.splits),
                "arrays": list(writer.specs),
                "versions": package_versions(),
                "collection_seconds_last_run": time.perf_counter() - start_time,
                IMPORT_RECORD: {
                    "settings": settings,
                    "camera": meta.camera,
                    "source_image_size": list(plan.folder.image_size),
                    "units": meta.units,
                    "source_episodes": [e.name for e in plan.folder.episodes],
                    "windows": [list(window) for window in plan.windows],
                },
            }
        )
    logger.info("Dataset %s imported: %s", path, plan.splits)
    return path
