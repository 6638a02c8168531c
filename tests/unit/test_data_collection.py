"""Collection into on-disk datasets with the fake push env: splits, resumption, unstable runs,
interruptions, a full disk, a second collector in the same folder, variable object counts,
checksums (``verify_dataset``, its command line, a resume over corrupt episodes)."""

from __future__ import annotations

import errno
import functools
import json
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import torch
from tensordict import TensorDict

import kinet_rl.data.collection
from fake_push_env import make_fake_env
from kinet_rl.atomic import DirectoryInUseError, DiskFullError, directory_lock
from kinet_rl.config_schema import ConfigError
from kinet_rl.data import (
    CorruptEpisode,
    DatasetChecksumError,
    DatasetIncompleteError,
    DatasetMismatchError,
    collect_dataset,
    load_dataset,
    split_ranges,
    verify_dataset,
)
from kinet_rl.data.object_counts import chunk_object_count
from kinet_rl.data.storage import EPISODES_DIR, PROGRESS_FILE, EpisodeWriter
from kinet_rl.data.verify import main as verify_command

ENV_CONFIG = {"task": "fake", "camera": "top", "image_size": 8}


def collect(
    root: Path, name: str, unstable_prob: float = 0.1, num_objects: int = 3, **kwargs
) -> Path:
    env_fn = functools.partial(
        make_fake_env,
        num_objects=num_objects,
        image_size=8,
        max_steps=4,
        unstable_prob=unstable_prob,
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


def collect_first_chunk(root: Path, name: str, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Collects like :func:`collect` until a simulated kill right after the first commit."""
    original_commit = EpisodeWriter.commit

    def commit_then_crash(self, *args, **kwargs):
        original_commit(self, *args, **kwargs)
        raise KeyboardInterrupt("simulated kill after the first chunk")

    with monkeypatch.context() as patch:
        patch.setattr(EpisodeWriter, "commit", commit_then_crash)
        with pytest.raises(KeyboardInterrupt):
            collect(root, name)
    return root / name


def test_resume_after_crash_gives_the_uninterrupted_dataset(
    reference: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    collect_first_chunk(tmp_path, "resumed", monkeypatch)
    with pytest.raises(DatasetIncompleteError, match="3/10 episodes.*resume"):
        load_dataset(tmp_path / "resumed")
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


def interrupt_each_collector(monkeypatch: pytest.MonkeyPatch, batches: int) -> None:
    """Makes every collector of the collection an :class:`InterruptedCollector` at ``batches``."""
    make_collector = kinet_rl.data.collection.make_collector
    monkeypatch.setattr(
        kinet_rl.data.collection,
        "make_collector",
        lambda *args, **kwargs: InterruptedCollector(make_collector(*args, **kwargs), batches),
    )


def test_an_interrupt_keeps_every_finished_episode_and_resumes(
    reference: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    interrupt_each_collector(monkeypatch, 5)
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


COUNT_RANGE = (1, 3)


def assert_same_episodes(a: Path, b: Path) -> None:
    """The two datasets store equal arrays (NaN padding equal to NaN padding)."""
    first, second = stored(a), stored(b)
    assert set(first.keys()) == set(second.keys())
    for key in first.keys():  # noqa: SIM118 (iterating a TensorDict yields its rows)
        assert torch.equal(first[key].nan_to_num(), second[key].nan_to_num()), key


@pytest.fixture(scope="module")
def variable_reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """10 episodes of 1 to 3 objects, a count per chunk of 3 source episodes."""
    return collect(tmp_path_factory.mktemp("data"), "variable", num_objects_range=COUNT_RANGE)


def test_object_counts_are_drawn_per_chunk_within_the_range_and_cover_it(
    variable_reference: Path,
) -> None:
    draws = [chunk_object_count(7, chunk, (2, 4)) for chunk in range(60)]
    assert set(draws) == {2, 3, 4}
    assert draws != [chunk_object_count(8, chunk, (2, 4)) for chunk in range(60)]
    episodes = stored(variable_reference)
    counts, source = episodes["num_objects"].tolist(), episodes["source_episode"].tolist()
    assert set(counts) == {1, 2, 3}  # this seed's 10 episodes cover the range
    assert counts == [chunk_object_count(7, s // 3, COUNT_RANGE) for s in source]
    metadata = load_dataset(variable_reference).metadata
    assert metadata["num_objects_range"] == list(COUNT_RANGE) and metadata["num_objects"] == 3
    assert metadata["arrays"][-1] == "num_objects"


def test_objects_beyond_the_episode_count_are_nan(variable_reference: Path) -> None:
    episodes = stored(variable_reference)
    counts = episodes["num_objects"]
    present = torch.arange(3) < counts[:, None]  # [E, N]
    pos_present = ~episodes["object_pos"].isnan().any(-1)  # [E, T+1, N]
    assert torch.equal(pos_present, present[:, None].expand_as(pos_present))
    yaw_present = ~episodes["object_yaw"].isnan()
    assert torch.equal(yaw_present, present[:, None].expand_as(yaw_present))
    assert torch.equal(~episodes["object_shape"].isnan().any(-1), present)


def test_each_episode_is_the_fixed_count_episode_of_its_index(tmp_path: Path) -> None:
    variable = stored(collect(tmp_path, "variable", 0.0, num_episodes=9, num_objects_range=(1, 3)))
    for count in variable["num_objects"].unique().tolist():
        fixed = stored(collect(tmp_path, f"fixed{count}", 0.0, num_episodes=9, num_objects=count))
        same = variable["num_objects"] == count
        assert torch.equal(variable["pixels"][same], fixed["pixels"][same])
        assert torch.equal(variable["action"][same], fixed["action"][same])
        assert torch.equal(variable["object_pos"][same][:, :, :count], fixed["object_pos"][same])


def test_same_seed_same_variable_dataset_other_seed_other_counts(
    variable_reference: Path, tmp_path: Path
) -> None:
    again = collect(tmp_path, "again", num_objects_range=COUNT_RANGE)
    assert_same_episodes(again, variable_reference)
    other = collect(tmp_path, "other", seed=8, num_objects_range=COUNT_RANGE)
    assert not torch.equal(stored(other)["num_objects"], stored(variable_reference)["num_objects"])


def test_a_variable_collection_interrupted_mid_chunk_resumes_to_the_same_dataset(
    variable_reference: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    interrupt_each_collector(monkeypatch, 2)  # one collector per chunk of 3
    with pytest.raises(KeyboardInterrupt):
        collect(tmp_path, "interrupted", num_objects_range=COUNT_RANGE)
    assert progress_of(tmp_path / "interrupted")["processed"] == 2  # inside the first chunk
    monkeypatch.undo()
    with pytest.raises(DatasetMismatchError, match="other settings"):  # the chunks decide counts
        collect(tmp_path, "interrupted", num_objects_range=COUNT_RANGE, chunk_episodes=4)
    collect(tmp_path, "interrupted", num_objects_range=COUNT_RANGE)
    assert_same_episodes(tmp_path / "interrupted", variable_reference)
    assert (
        load_dataset(tmp_path / "interrupted").metadata["discarded_unstable"]
        == (load_dataset(variable_reference).metadata["discarded_unstable"])
    )


def test_a_fixed_count_collection_stores_and_records_no_counts(reference: Path) -> None:
    assert "num_objects" not in stored(reference).keys()  # noqa: SIM118
    assert "num_objects_range" not in load_dataset(reference).metadata
    assert set(progress_of(reference)["settings"]) == {
        "env", "seed", "num_episodes", "episode_length", "image_size", "num_objects",
        "workspace_half_size", "policy", "splits",
    }  # fmt: skip


@pytest.mark.parametrize("bad", [(0, 2), (2, 6), (3, 2)])
def test_a_bad_object_count_range_is_refused_before_collecting(bad, tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"num_objects_range: got \[.*1 <= low <= high <= 5"):
        collect(tmp_path, "bad", num_objects_range=bad)
    assert not (tmp_path / "bad").exists()


def flip_frame_bytes(path: Path, episode: int, frame: int = 2, count: int = 64) -> None:
    """Inverts ``count`` bytes in the middle of stored frame ``frame`` of ``episode``."""
    _, frames, height, width, channels = stored(path)["pixels"].shape
    frame_bytes = height * width * channels
    offset = (episode * frames + frame) * frame_bytes + (frame_bytes - count) // 2
    with open(path / EPISODES_DIR / "pixels.memmap", "r+b") as f:
        f.seek(offset)
        flipped = bytes(byte ^ 0xFF for byte in f.read(count))
        f.seek(offset)
        f.write(flipped)


def test_a_clean_dataset_verifies(reference: Path, capsys: pytest.CaptureFixture[str]) -> None:
    report = verify_dataset(reference)
    assert report.verified and report.complete and report.checked == report.episodes == 10
    report.raise_if_corrupt()
    assert verify_command([str(reference)]) == 0
    assert "OK: 10 of 10 episodes match their sha256 checksums" in capsys.readouterr().out


def test_flipped_bytes_in_a_stored_frame_name_their_episode(
    reference: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = shutil.copytree(reference, tmp_path / "copy")
    flip_frame_bytes(path, episode=8)  # splits of 10 episodes: train 0-7, val 8, test 9
    load_dataset(path, "val").sample(4)  # loading does not read the checksums
    report = verify_dataset(path)
    assert report.corrupt == (CorruptEpisode(8, "val"),) and report.checked == 10
    assert not report.ok and not report.verified
    with pytest.raises(DatasetChecksumError, match=r"CORRUPT.*episode\(s\) 8 \(val\)") as err:
        report.raise_if_corrupt()
    assert err.value.episodes == [8]
    assert verify_command([str(reference), str(path)]) == 1
    out = capsys.readouterr().out
    assert f"{reference}: OK" in out and f"{path}: CORRUPT" in out and "8 (val)" in out


def test_a_dataset_without_checksums_is_reported_as_unverified(
    reference: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = shutil.copytree(reference, tmp_path / "old")
    progress = progress_of(path)
    del progress["checksums"]  # as written before checksums were recorded
    (path / PROGRESS_FILE).write_text(json.dumps(progress))
    report = verify_dataset(path)
    assert not report.checksums_present and report.ok and not report.verified
    assert "NOT VERIFIED: no checksums recorded" in report.summary()
    assert verify_command([str(path)]) == 2
    assert "cannot be checked" in capsys.readouterr().out
    assert load_dataset(path).num_episodes == 8  # it still loads


def test_a_resume_refuses_corrupt_reused_episodes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = collect_first_chunk(tmp_path, "partial", monkeypatch)
    flip_frame_bytes(path, episode=1)
    assert verify_dataset(path).corrupt == (CorruptEpisode(1, "train"),)
    with pytest.raises(DatasetChecksumError, match=r"Cannot resume .*episodes \[1\].*Delete"):
        collect(tmp_path, "partial")
    assert progress_of(path)["committed"] == 3  # nothing was built on them


def test_a_resume_of_a_collection_without_checksums_checks_the_new_episodes(
    reference: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = collect_first_chunk(tmp_path, "old", monkeypatch)
    progress = progress_of(path)
    del progress["checksums"]  # started before checksums were recorded
    (path / PROGRESS_FILE).write_text(json.dumps(progress))
    collect(tmp_path, "old")
    report = verify_dataset(path)
    assert report.ok and report.checked == 7 and not report.verified
    assert "3 episodes were committed without checksums" in report.summary()
    assert progress_of(path)["checksums"] == progress_of(reference)["checksums"] | {
        "episodes": [None] * 3 + progress_of(reference)["checksums"]["episodes"][3:]
    }
