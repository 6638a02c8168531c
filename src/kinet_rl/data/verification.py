"""Checking a dataset's stored bytes against the checksums recorded when they were written.

Every commit of :class:`~kinet_rl.data.storage.EpisodeWriter` records one SHA-256 digest per
episode over its rows of every stored array (pixels, actions, poses, shapes, indices);
:func:`verify_dataset` recomputes them and names the episodes that differ, with their split.
The command line is :mod:`kinet_rl.data.verify`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from kinet_rl.data.collection import split_ranges
from kinet_rl.data.dataset import ALL_SPLITS, PushDataset
from kinet_rl.data.storage import (
    CHECKSUM_ALGORITHM,
    COLLECT_HINT,
    METADATA_FILE,
    PROGRESS_FILE,
    DatasetChecksumError,
    DatasetCorruptError,
    DatasetNotFoundError,
    mismatched_episodes,
    open_episodes,
    read_json,
    recorded_checksums,
)


@dataclass(frozen=True)
class CorruptEpisode:
    """A stored episode whose bytes differ from its recorded checksum.

    Attributes:
        episode: its index in the stored arrays (the ``episode`` of ``load_dataset(path, "all")``
            batches; a split's batches use the same indices).
        split: the split holding it, or None if the dataset records no splits.
    """

    episode: int
    split: str | None

    def __str__(self) -> str:
        return str(self.episode) if self.split is None else f"{self.episode} ({self.split})"


@dataclass(frozen=True)
class VerifyReport:
    """What :func:`verify_dataset` found.

    Attributes:
        path: the dataset folder.
        complete: the dataset is marked complete (else: its committed episodes were checked).
        episodes: stored (committed) episodes.
        checksums_present: the dataset records checksums (datasets of older kinet_rl do not).
        checked: episodes compared with their recorded checksum (fewer than ``episodes`` when
            a collection started by an older kinet_rl was resumed by a newer one).
        corrupt: the episodes whose stored bytes differ from their checksum.
        seconds: wall time of the check.
    """

    path: Path
    complete: bool
    episodes: int
    checksums_present: bool
    checked: int
    corrupt: tuple[CorruptEpisode, ...]
    seconds: float

    @property
    def ok(self) -> bool:
        """No checked episode differs from its checksum (True also when none was checked)."""
        return not self.corrupt

    @property
    def verified(self) -> bool:
        """Every stored episode was checked and matches its checksum."""
        return self.ok and self.checksums_present and self.checked == self.episodes

    def summary(self) -> str:
        """A few lines that say what was checked, what differs and what to do."""
        which = "" if self.complete else " (partial dataset: its committed episodes)"
        if not self.checksums_present:
            return (
                f"{self.path}: NOT VERIFIED: no checksums recorded (collected by a kinet_rl "
                f"older than dataset checksums); its {self.episodes} episodes{which} cannot be "
                f"checked. Collect it again to get checksums: {COLLECT_HINT}"
            )
        unchecked = self.episodes - self.checked
        skipped = (
            f" {unchecked} episodes were committed without checksums (by an older kinet_rl "
            "before a resume) and were not checked."
            if unchecked
            else ""
        )
        if self.ok:
            return (
                f"{self.path}: OK: {self.checked} of {self.episodes} episodes{which} match their "
                f"{CHECKSUM_ALGORITHM} checksums ({self.seconds:.1f} s).{skipped}"
            )
        episodes = ", ".join(str(episode) for episode in self.corrupt)
        return (
            f"{self.path}: CORRUPT: {len(self.corrupt)} of {self.checked} checked episodes{which} "
            f"differ from the checksums recorded when they were written: episode(s) {episodes}. "
            "Their stored bytes changed since (a disk, memory or copy error, or an edit), so "
            "training and evaluation would read damaged frames, pushes or poses. Copy the "
            f"dataset again from an intact copy, or delete {self.path} and collect it again: "
            f"{COLLECT_HINT}.{skipped}"
        )

    def raise_if_corrupt(self) -> None:
        """Raises :class:`DatasetChecksumError` (with :meth:`summary`) if an episode differs."""
        if self.corrupt:
            raise DatasetChecksumError(self.summary(), [c.episode for c in self.corrupt])


def verify_dataset(path: str | Path) -> VerifyReport:
    """Recomputes the checksum of every stored episode of ``path`` and compares it.

    Reads every array file once (memory-mapped). A partial dataset (an interrupted
    collection) has its committed episodes checked; a dataset without checksums (collected by
    an older kinet_rl) loads as before and is reported with ``checksums_present`` False.
    Corrupt episodes are reported, not raised (see :meth:`VerifyReport.raise_if_corrupt`).

    Raises:
        DatasetNotFoundError: no dataset at ``path``.
        DatasetCorruptError: its records or array files are unreadable, truncated or
            inconsistent (what :func:`~kinet_rl.data.load_dataset` refuses too).
    """
    path = Path(path)
    start = time.perf_counter()
    progress = read_json(path / PROGRESS_FILE) if (path / PROGRESS_FILE).exists() else {}
    if (path / METADATA_FILE).exists():
        metadata = PushDataset(path, split=ALL_SPLITS).metadata  # the loader's checks
        complete, episodes, splits = True, int(metadata["num_episodes"]), metadata["splits"]
    elif progress:
        settings = progress.get("settings", {})
        complete, episodes = False, int(progress["committed"])
        splits = (
            split_ranges(settings["num_episodes"], settings["splits"])
            if "splits" in settings and "num_episodes" in settings
            else {}
        )
    else:
        raise DatasetNotFoundError(f"No dataset at {path}. Collect it with: {COLLECT_HINT}")
    recorded = recorded_checksums(path, progress) if progress else None
    if recorded is None:
        return VerifyReport(path, complete, episodes, False, 0, (), time.perf_counter() - start)
    arrays, digests = recorded
    storage = open_episodes(path)
    missing = sorted(set(arrays) - set(storage.keys()))
    if len(digests) != episodes or missing:
        raise DatasetCorruptError(
            f"{path / PROGRESS_FILE} records checksums of {len(digests)} episodes of the arrays "
            f"{arrays}, but {path} holds {episodes} episodes and lacks {missing}. Delete {path} "
            f"and collect it again: {COLLECT_HINT}"
        )
    corrupt = tuple(
        CorruptEpisode(
            episode,
            next((name for name, (lo, hi) in splits.items() if lo <= episode < hi), None),
        )
        for episode in mismatched_episodes(storage, arrays, digests)
    )
    checked = sum(digest is not None for digest in digests)
    return VerifyReport(
        path, complete, episodes, True, checked, corrupt, time.perf_counter() - start
    )
