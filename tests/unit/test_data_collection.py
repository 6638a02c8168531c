"""Collection into on-disk datasets with the fake push env: splits, resumption, unstable runs,
interruptions, a full disk and a second collector in the same folder."""

from __future__ import annotations

import errno
import functools
import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import torch
from tensordict import TensorDict

import kinet_rl.data.collection
from fake_push_env import make_fake_env
from kinet_rl.atomic import DirectoryInUseError, DiskFullError, directory_lock
from kinet_rl.data import (
    DatasetIncompleteError,
    DatasetMismatchError,
    collect_dataset,
    load_dataset,
    split_ranges,
)
from kinet_rl.data.storage import EPISODES_DIR, PROGRESS_FILE, EpisodeWriter

ENV_CONFIG = {"task": "fake", "camera": "top", "image_size": 8}


def collect(root: Path, name: str, unstable_prob: float = 0.1, **kwargs) -> Path:
    env_fn = functools.partial(
        make_fake_env, image_size=8, max_steps=4, unstable_prob=unstable_prob
    )
    settings = {"num_episodes": 10, "num_workers": 1, "chunk_episodes": 3, "seed": 7}
    settings.update(kwargs)
    return collect_dataset(env_fn, ENV_CONFIG, root=root, name=name, progress=False, **settings)


def stored(path: Path) -> TensorDict:
    return TensorDict.load_memmap(path / EPISODES_DIR)


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return collect(tmp_path_factory.mktemp("data"), "reference")


def test_splits_are_disjoint_and_cover_all_episodes(reference: Path) -> None:
    covered = []
    for split in ("train", "val", "test"):
        data = load_dataset(reference, split)
        covered += range(data.episode_start, data.episode_stop)
        episodes = data.sample(64, generator=torch.Generator().manual_seed(0))["episode"]
        assert episodes.min() >= data.episode_start and episodes.max() < data.episode_stop
    assert sorted(covered) == list(range(10))
    assert load_dataset(reference, "train").num_episodes == 8


@pytest.mark.parametrize("num_episodes", [1, 3, 7, 10, 8000])
def test_split_ranges_partition_the_episodes(num_episodes: int) -> None:
    ranges = split_ranges(num_episodes, {"train": 0.8, "val": 0.1, "test": 0.1})
    flat = [i for start, stop in ranges.values() for i in range(start, stop)]
    assert flat == list(range(num_episodes))


def test_resume_after_crash_gives_the_uninterrupted_dataset(
    reference: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    original_commit = EpisodeWriter.commit

    def commit_then_crash(self, *args, **kwargs):
        original_commit(self, *args, **kwargs)
        raise KeyboardInterrupt("simulated kill after the first chunk")

    monkeypatch.setattr(EpisodeWriter, "commit", commit_then_crash)
    with pytest.raises(KeyboardInterrupt):
        collect(tmp_path, "resumed")
    with pytest.raises(DatasetIncompleteError, match="3/10 episodes.*resume"):
        load_dataset(tmp_path / "resumed")
    monkeypatch.setattr(EpisodeWriter, "commit", original_commit)
    collect(tmp_path, "resumed")
    assert (stored(tmp_path / "resumed") == stored(reference)).all()
    resumed, full = (load_dataset(p).metadata for p in (tmp_path / "resumed", reference))
    assert resumed["discarded_unstable"] == full["discarded_unstable"]


def test_unstable_episodes_are_discarded_and_counted(reference: Path) -> None:
    metadata = load_dataset(reference).metadata
    source = stored(reference)["source_episode"].tolist()
    assert source == sorted(source) and len(set(source)) == 10
    gaps = source[-1] + 1 - len(source)
    assert metadata["discarded_unstable"] == gaps > 0
    assert metadata["processed_episodes"] == source[-1] + 1


def test_same_seed_same_data_other_seed_other_data(reference: Path, tmp_path: Path) -> None:
    again = collect(tmp_path, "again", chunk_episodes=4)
    other = collect(tmp_path, "other", seed=8, num_episodes=2)
    assert (stored(again) == stored(reference)).all()
    assert not torch.equal(stored(other)["pixels"], stored(reference)["pixels"][:2])


def test_resume_with_other_settings_is_refused(tmp_path: Path, monkeypatch) -> None:
    def crash(self, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(EpisodeWriter, "commit", crash)
    with pytest.raises(KeyboardInterrupt):
        collect(tmp_path, "changed")
    monkeypatch.undo()
    with pytest.raises(DatasetMismatchError, match="other settings.*delete"):
        collect(tmp_path, "changed", seed=99)


def test_runaway_instability_aborts(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError, match="went unstable"):
        collect(tmp_path, "unstable", unstable_prob=0.9, num_episodes=3)


def test_unknown_backend_and_distributed_options_are_refused(tmp_path: Path) -> None:
    with pytest.raises(
        ValueError, match=r"backend: got 'ray', expected one of \('local', 'distributed'\)"
    ):
        collect(tmp_path, "bad", backend="ray")
    with pytest.raises(ValueError, match="distributed.frames_per_batch: unknown key"):
        collect(tmp_path, "bad", backend="distributed", distributed={"frames_per_batch": 3})
    assert not (tmp_path / "bad").exists()


class InterruptedCollector:
    """A collector that is interrupted (KeyboardInterrupt) while its caller waits for batch ``n``."""

    def __init__(self, collector: Any, batches: int) -> None:
        self.collector, self.batches = collector, batches

    def __iter__(self) -> Iterator[Any]:
        for i, batch in enumerate(self.collector):
            if i == self.batches:
                raise KeyboardInterrupt
            yield batch

    def shutdown(self, timeout: float | None = None) -> None:
        self.collector.shutdown(timeout=timeout)


def progress_of(path: Path) -> dict[str, Any]:
    return json.loads((path / PROGRESS_FILE).read_text())


def test_an_interrupt_keeps_every_finished_episode_and_resumes(
    reference: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    make_collector = kinet_rl.data.collection.make_collector
    monkeypatch.setattr(
        kinet_rl.data.collection,
        "make_collector",
        lambda *args, **kwargs: InterruptedCollector(make_collector(*args, **kwargs), 5),
    )
    with pytest.raises(KeyboardInterrupt):
        collect(tmp_path, "interrupted")  # chunks of 3, one episode per batch
    progress = progress_of(tmp_path / "interrupted")
    assert progress["processed"] == 5  # the open chunk was committed, not lost
    assert progress["committed"] == 5 - progress["discarded_unstable"] > 3
    monkeypatch.undo()
    collect(tmp_path, "interrupted")
    assert (stored(tmp_path / "interrupted") == stored(reference)).all()


def test_a_full_disk_midway_keeps_the_last_commit_and_resumes(
    reference: Path, tmp_path: Path, full_disk: Callable[[int], None], monkeypatch
) -> None:
    full_disk(2)  # the first progress record and the first chunk's fit, the second chunk's not
    with pytest.raises(DiskFullError, match=f"Cannot write {tmp_path / 'full' / PROGRESS_FILE}"):
        collect(tmp_path, "full")
    assert progress_of(tmp_path / "full")["committed"] == 3
    monkeypatch.undo()
    collect(tmp_path, "full")
    assert (stored(tmp_path / "full") == stored(reference)).all()


def test_a_dataset_too_large_for_the_disk_fails_before_collecting(
    reference: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_space(fd: int, offset: int, length: int) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr("os.posix_fallocate", no_space)
    with pytest.raises(DiskFullError, match="Not enough disk space under .*huge for the dataset"):
        collect(tmp_path, "huge")
    assert sorted(p.name for p in (tmp_path / "huge").iterdir()) == [".lock"]
    monkeypatch.undo()
    collect(tmp_path, "huge")  # nothing stale is left in the way
    assert (stored(tmp_path / "huge") == stored(reference)).all()


def test_a_second_collection_into_the_same_folder_is_refused(tmp_path: Path) -> None:
    with directory_lock(tmp_path / "busy", "collecting a dataset"):
        with pytest.raises(DirectoryInUseError, match="busy is in use.*is collecting a dataset"):
            collect(tmp_path, "busy")
        assert not (tmp_path / "busy" / PROGRESS_FILE).exists()
