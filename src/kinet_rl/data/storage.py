"""On-disk episode storage: memory-mapped arrays, atomic progress and completion records.

Layout of ``<root>/<name>/``::

    episodes/          tensordict memmap (TensorDict.memmap_like), batch [E]:
      pixels.memmap          uint8 [E, T+1, H, W, 3]  each frame stored once
      action.memmap          float32 [E, T, 4]
      object_pos.memmap      float32 [E, T+1, N, 2]
      object_yaw.memmap      float32 [E, T+1, N]
      object_shape.memmap    float32 [E, N, 8]  body-frame footprints, one per episode (optional)
      source_episode.memmap  int64 [E]  episode index within the collection run
      num_objects.memmap     int64 [E]  objects per episode (variable-count datasets only;
                             their object arrays hold NaN beyond it, N = the range's high)
      meta.json              tensordict's own shapes and dtypes
    progress.json      committed episodes, processed (kept + discarded) source episodes, settings,
                       and ``checksums``: the SHA-256 of every committed episode's stored bytes
    metadata.json      written last, atomically: its presence marks the dataset complete;
                       ``arrays`` lists the stored arrays

A dataset without object state (pixels and pushes only, imported from a robot's recordings by
:mod:`kinet_rl.data.importing`) has no per-object array: its metadata records ``num_objects``
null and ``arrays`` without them.

Datasets collected before ``object_shape`` was stored have no ``arrays`` entry and no such file;
they load for every model that does not need the shapes (see :data:`OPTIONAL_ARRAYS`). A
variable-count dataset records ``num_objects_range`` ``[low, high]`` in its metadata
(:mod:`kinet_rl.data.object_counts`).

Each commit records, in the same atomic replacement of ``progress.json``, one SHA-256 digest per
committed episode over its rows of every stored array (:func:`episode_digests`); a resumed
writer checks the episodes it builds on, and :func:`kinet_rl.data.verify_dataset` checks a
dataset. Datasets written before checksums were recorded have none (``checksums`` absent, or
None for the episodes committed before a resume by a newer kinet_rl).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase

from kinet_rl.atomic import DISK_FULL_ERRNOS, DiskFullError, atomic_write_json
from kinet_rl.data.object_counts import pad_objects
from kinet_rl.keys import ACTION, OBJECT_COUNT, OBJECT_POS, OBJECT_SHAPE, OBJECT_YAW, PIXELS

logger = logging.getLogger(__name__)

EPISODES_DIR = "episodes"
PROGRESS_FILE = "progress.json"
METADATA_FILE = "metadata.json"
FORMAT_VERSION = 1
COLLECT_HINT = "python -m kinet_rl.collect [+exp=<experiment>] data.root=<root> data.name=<name>"
#: Arrays that datasets of older kinet_rl versions lack (their metadata has no ``arrays``).
OPTIONAL_ARRAYS = (OBJECT_SHAPE,)
#: ``hashlib`` name of the per-episode digests in ``progress.json``'s ``checksums``.
CHECKSUM_ALGORITHM = "sha256"
#: ``metadata.json`` entry of an imported dataset: where it came from and how it was converted
#: (:mod:`kinet_rl.data.importing`); collected datasets have none.
IMPORT_RECORD = "imported"


class DatasetError(Exception):
    """Base class of dataset errors; the message names the problem and the fix."""


class DatasetNotFoundError(DatasetError):
    """No dataset exists at the given path."""


class DatasetIncompleteError(DatasetError):
    """The dataset's collection stopped before it was marked complete."""


class DatasetCorruptError(DatasetError):
    """The dataset's files are unreadable, truncated or inconsistent."""


class DatasetMismatchError(DatasetError):
    """The dataset differs from what the caller expects, or from the settings of a resumed run."""


class DatasetChecksumError(DatasetCorruptError):
    """Stored episodes differ from the checksums recorded when they were written.

    Attributes:
        episodes: the corrupt episodes' indices in the stored arrays.
    """

    def __init__(self, message: str, episodes: Sequence[int]) -> None:
        super().__init__(message)
        self.episodes = list(episodes)


def read_json(path: Path) -> dict[str, Any]:
    """Reads a JSON record, raising :class:`DatasetCorruptError` if it cannot be parsed."""
    try:
        with open(path) as f:
            record = json.load(f)
    except (OSError, json.JSONDecodeError) as err:
        raise DatasetCorruptError(
            f"Cannot read {path} ({err}). Delete {path.parent} and collect it again: {COLLECT_HINT}"
        ) from err
    if not isinstance(record, dict):
        raise DatasetCorruptError(
            f"Cannot read {path} (a JSON {type(record).__name__}, not an object). Delete "
            f"{path.parent} and collect it again: {COLLECT_HINT}"
        )
    return record


def stored_episodes(path: Path) -> tuple[int, bool]:
    """Episodes the dataset folder ``path`` holds so far, and whether it is complete.

    A complete dataset counts its recorded ``num_episodes``, a partial one its committed
    episodes; a folder without either record holds 0.
    """
    if (path / METADATA_FILE).exists():
        return int(read_json(path / METADATA_FILE)["num_episodes"]), True
    if (path / PROGRESS_FILE).exists():
        return int(read_json(path / PROGRESS_FILE)["committed"]), False
    return 0, False


def imported_metadata(path: Path) -> dict[str, Any] | None:
    """The metadata of the complete dataset folder ``path`` if it was imported (it has an
    :data:`IMPORT_RECORD`), else None (collected, partial or missing)."""
    if not (path / METADATA_FILE).exists():
        return None
    metadata = read_json(path / METADATA_FILE)
    return metadata if metadata.get(IMPORT_RECORD) is not None else None


def open_episodes(path: Path) -> TensorDict:
    """The memory-mapped episode arrays of the dataset folder ``path`` (no copy).

    Raises:
        DatasetCorruptError: tensordict cannot open them.
    """
    try:
        return TensorDict.load_memmap(path / EPISODES_DIR)
    except Exception as err:  # tensordict raises several types for a damaged folder
        raise DatasetCorruptError(
            f"Cannot open the arrays in {path / EPISODES_DIR} ({type(err).__name__}: {err}). "
            f"Delete {path} and collect it again: {COLLECT_HINT}"
        ) from err


def episode_digests(
    storage: TensorDictBase, names: Sequence[str], start: int, stop: int
) -> list[str]:
    """SHA-256 hex digests of the stored episodes ``start:stop``, one per episode.

    An episode's digest covers its rows of the arrays ``names``, in that order, as stored
    (raw bytes, NaN padding included).
    """
    arrays = [storage.get(name).as_subclass(torch.Tensor) for name in names]
    digests = []
    for episode in range(start, stop):
        digest = hashlib.new(CHECKSUM_ALGORITHM)
        for array in arrays:
            digest.update(array[episode].contiguous().numpy())
        digests.append(digest.hexdigest())
    return digests


def recorded_checksums(
    path: Path, progress: Mapping[str, Any]
) -> tuple[list[str], list[str | None]] | None:
    """The arrays and the per-episode digests (None: committed without one) that the progress
    record ``progress`` of dataset ``path`` holds, or None if it has no checksums (an older
    kinet_rl wrote it).

    Raises:
        DatasetCorruptError: the record is malformed.
    """
    record = progress.get("checksums")
    if record is None:
        return None
    committed = int(progress["committed"])
    if (
        not isinstance(record, dict)
        or record.get("algorithm") != CHECKSUM_ALGORITHM
        or not isinstance(record.get("arrays"), list)
        or not isinstance(record.get("episodes"), list)
        or len(record["episodes"]) != committed
    ):
        raise DatasetCorruptError(
            f"The checksum record in {path / PROGRESS_FILE} is malformed (expected "
            f"{CHECKSUM_ALGORITHM} digests of {committed} episodes). Delete {path} and collect "
            f"it again: {COLLECT_HINT}"
        )
    return record["arrays"], record["episodes"]


def mismatched_episodes(
    storage: TensorDictBase, names: Sequence[str], recorded: Sequence[str | None]
) -> list[int]:
    """Indices of the stored episodes whose digest differs from ``recorded`` (None: unchecked)."""
    actual = episode_digests(storage, names, 0, len(recorded))
    return [
        episode
        for episode, (expected, digest) in enumerate(zip(recorded, actual, strict=True))
        if expected is not None and expected != digest
    ]


def episode_array_specs(
    episode_length: int,
    image_size: int,
    num_objects: int | None,
    variable_object_count: bool = False,
) -> dict[str, tuple[tuple[int, ...], torch.dtype]]:
    """Per-episode shape (without the leading E) and dtype of every stored array.

    ``num_objects`` None: episodes without object state (pixels and pushes only, e.g. imported
    from a robot's recordings; :mod:`kinet_rl.data.importing`), so no per-object array.
    ``variable_object_count`` adds the per-episode object count (``num_objects`` objects are
    then the most an episode holds).
    """
    t, h, n = episode_length, image_size, num_objects
    specs: dict[str, tuple[tuple[int, ...], torch.dtype]] = {
        PIXELS: ((t + 1, h, h, 3), torch.uint8),
        ACTION: ((t, 4), torch.float32),
    }
    if n is not None:
        specs |= {
            OBJECT_POS: ((t + 1, n, 2), torch.float32),
            OBJECT_YAW: ((t + 1, n), torch.float32),
            OBJECT_SHAPE: ((n, 8), torch.float32),
        }
    specs["source_episode"] = ((), torch.int64)
    if variable_object_count:
        specs[OBJECT_COUNT] = ((), torch.int64)
    return specs


def stored_array_specs(
    metadata: Mapping[str, Any],
) -> dict[str, tuple[tuple[int, ...], torch.dtype]]:
    """:func:`episode_array_specs` of the arrays a complete dataset's ``metadata`` says it stores."""
    specs = episode_array_specs(
        metadata["episode_length"],
        metadata["image_size"],
        metadata["num_objects"],
        variable_object_count=metadata.get("num_objects_range") is not None,
    )
    names = metadata.get("arrays", [name for name in specs if name not in OPTIONAL_ARRAYS])
    return {name: spec for name, spec in specs.items() if name in names}


def check_array_files(path: Path, num_episodes: int, specs: Mapping[str, Any]) -> None:
    """Raises :class:`DatasetCorruptError` unless every array file has its expected size."""
    for name, (shape, dtype) in specs.items():
        file = path / EPISODES_DIR / f"{name}.memmap"
        expected = num_episodes * torch.Size(shape).numel() * dtype.itemsize
        size = file.stat().st_size if file.exists() else None
        if size != expected:
            found = "is missing" if size is None else f"has {size} bytes"
            raise DatasetCorruptError(
                f"{file} {found}, expected {expected} bytes: the dataset is truncated or "
                f"corrupt. Delete {path} and collect it again: {COLLECT_HINT}"
            )


class EpisodeWriter:
    """Appends fixed-length episodes, in order, to memory-mapped storage; resumable.

    Args:
        path: dataset folder ``<root>/<name>``.
        num_episodes: episodes the finished dataset holds (disk space is reserved up front).
        episode_length: pushes per episode T.
        image_size: frame side H = W.
        num_objects: objects per scene N (with ``variable_object_count``, the most per scene);
            None: episodes without object state (pixels, pushes and source index only).
        settings: JSON-able collection settings; a resumed run must present the same ones.
        variable_object_count: episodes hold up to ``num_objects`` objects: each commit's
            per-object arrays are NaN-padded and its object count is stored.
    """

    def __init__(
        self,
        path: Path,
        num_episodes: int,
        episode_length: int,
        image_size: int,
        num_objects: int | None,
        settings: Mapping[str, Any],
        variable_object_count: bool = False,
    ) -> None:
        self.path = Path(path)
        self.num_episodes = num_episodes
        self.num_objects = num_objects
        self.settings = dict(settings)
        self.specs = episode_array_specs(
            episode_length, image_size, num_objects, variable_object_count
        )
        progress_file = self.path / PROGRESS_FILE
        if progress_file.exists():
            progress = read_json(progress_file)
            if progress.get("settings") != json.loads(json.dumps(self.settings)):
                raise DatasetMismatchError(
                    f"{self.path} holds a partial collection started with other settings "
                    f"({progress.get('settings')}) than now ({self.settings}). Rerun with the "
                    f"original settings to resume, or delete {self.path} to start over."
                )
            check_array_files(self.path, num_episodes, self.specs)
            self.storage = open_episodes(self.path)
            self.committed = int(progress["committed"])
            self.processed = int(progress["processed"])
            self.discarded = int(progress["discarded_unstable"])
            self.checksums = self._verify_reused(progress)
            logger.info("Resuming %s at %d/%d episodes.", self.path, self.committed, num_episodes)
        else:
            self.path.mkdir(parents=True, exist_ok=True)
            template = TensorDict(
                {
                    name: torch.zeros((1, *shape), dtype=dtype).expand(num_episodes, *shape)
                    for name, (shape, dtype) in self.specs.items()
                },
                batch_size=[num_episodes],
            )
            self.storage = template.memmap_like(self.path / EPISODES_DIR)
            self._allocate()
            self.committed = self.processed = self.discarded = 0
            self.checksums = []
            self._write_progress()

    def _allocate(self) -> None:
        """Reserves the array files' disk space now, so that a full disk fails before collecting.

        Memory-mapped writes into an unallocated (sparse) file on a full disk would kill the
        process with SIGBUS instead of raising an error.
        """
        files = [self.path / EPISODES_DIR / f"{name}.memmap" for name in self.specs]
        sizes = [file.stat().st_size for file in files]
        for file, size in zip(files, sizes, strict=True):
            with open(file, "rb+") as f:
                try:
                    os.posix_fallocate(f.fileno(), 0, size)
                except OSError as err:
                    if err.errno not in DISK_FULL_ERRNOS:
                        raise
                    shutil.rmtree(self.path / EPISODES_DIR)
                    raise DiskFullError(
                        err.errno,
                        f"Not enough disk space under {self.path} for the dataset's "
                        f"{sum(sizes) / 1e9:.2f} GB ({self.num_episodes} episodes). Free space "
                        "there, or collect fewer episodes (data.num_episodes) or elsewhere "
                        "(data.root), then run the command again.",
                    ) from err

    def _verify_reused(self, progress: Mapping[str, Any]) -> list[str | None]:
        """Checks the committed episodes against their checksums; returns the checksums.

        Raises:
            DatasetChecksumError: some differ (the message names them and the fix).
        """
        recorded = recorded_checksums(self.path, progress)
        if recorded is None:
            logger.warning(
                "%s: its %d committed episodes were written without checksums (by an older "
                "kinet_rl) and cannot be verified; the episodes collected now get checksums.",
                self.path,
                self.committed,
            )
            return [None] * self.committed
        arrays, digests = recorded
        if arrays != list(self.specs):
            raise DatasetCorruptError(
                f"{self.path / PROGRESS_FILE} records checksums of the arrays {arrays}, but the "
                f"dataset stores {list(self.specs)}. Delete {self.path} and collect it again: "
                f"{COLLECT_HINT}"
            )
        corrupt = mismatched_episodes(self.storage, arrays, digests)
        if corrupt:
            raise DatasetChecksumError(
                f"Cannot resume {self.path}: the stored bytes of its episodes {corrupt} (of "
                f"{self.committed} committed) differ from the checksums recorded when they were "
                "written (a disk, memory or copy error, or an edit), and the rest of the "
                f"dataset would be built on them. Delete {self.path} and collect it again: "
                f"{COLLECT_HINT}",
                corrupt,
            )
        return list(digests)

    def _write_progress(self) -> None:
        atomic_write_json(
            self.path / PROGRESS_FILE,
            {
                "committed": self.committed,
                "processed": self.processed,
                "discarded_unstable": self.discarded,
                "num_episodes": self.num_episodes,
                "settings": self.settings,
                "checksums": {
                    "algorithm": CHECKSUM_ALGORITHM,
                    "arrays": list(self.specs),
                    "episodes": self.checksums,
                },
            },
        )

    def commit(self, episodes: TensorDictBase | None, processed: int, discarded: int) -> None:
        """Writes ``episodes`` [k] after the committed ones, syncs, then records progress and
        the new episodes' checksums (one atomic write).

        Args:
            episodes: batch [k] with the stored arrays' keys (for a variable-count dataset: of
                one object count, unpadded), or None to record progress alone.
            processed: source episodes accounted for (kept or discarded) after this commit.
            discarded: unstable source episodes discarded so far.
        """
        stop = self.committed
        if episodes is not None:
            stop += episodes.shape[0]
            if stop > self.num_episodes:
                raise ValueError(
                    f"Commit of {episodes.shape[0]} episodes overflows {self.num_episodes}."
                )
            if OBJECT_COUNT in self.specs:
                episodes = pad_objects(episodes, self.num_objects)
            self.storage[self.committed : stop] = episodes.select(*self.specs)
            for name in self.specs:
                with open(self.path / EPISODES_DIR / f"{name}.memmap", "rb+") as f:
                    os.fsync(f.fileno())
            self.checksums += episode_digests(self.storage, list(self.specs), self.committed, stop)
        self.committed, self.processed, self.discarded = stop, processed, discarded
        self._write_progress()

    def finalize(self, metadata: Mapping[str, Any]) -> None:
        """Marks the dataset complete by writing ``metadata.json`` atomically."""
        if self.committed != self.num_episodes:
            raise RuntimeError(f"finalize() at {self.committed}/{self.num_episodes} episodes.")
        atomic_write_json(self.path / METADATA_FILE, metadata)
