"""Atomic writes on a full disk keep the previous file; directory locks refuse a second writer."""

from __future__ import annotations

import errno
import os
import signal
from collections.abc import Callable
from pathlib import Path

import pytest
import torch

from kinet_rl.atomic import (
    DirectoryInUseError,
    DiskFullError,
    atomic_torch_save,
    atomic_write_json,
    directory_lock,
    safe_torch_load,
)


def test_a_full_disk_keeps_the_previous_file_and_says_what_to_do(
    tmp_path: Path, full_disk: Callable[[int], None]
) -> None:
    path = tmp_path / "progress.json"
    atomic_write_json(path, {"committed": 3})
    before = path.read_text()
    full_disk(0)
    with pytest.raises(DiskFullError, match=f"Cannot write {path}: no space left") as caught:
        atomic_write_json(path, {"committed": 6})
    assert caught.value.errno == errno.ENOSPC and "run the same command again" in str(caught.value)
    assert path.read_text() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["progress.json"]  # no temporary file


def test_a_checkpoint_that_does_not_fit_leaves_the_last_one_loadable(
    tmp_path: Path, full_disk: Callable[[int], None]
) -> None:
    path = tmp_path / "last.pt"
    atomic_torch_save({"step": 2, "w": torch.ones(3)}, path)
    full_disk(0)
    with pytest.raises(DiskFullError, match="last.pt keeps its previous complete version"):
        atomic_torch_save({"step": 4, "w": torch.zeros(100_000)}, path)
    assert safe_torch_load(path)["step"] == 2


def test_a_locked_directory_refuses_a_second_writer_until_released(tmp_path: Path) -> None:
    with directory_lock(tmp_path / "run", "training"):
        assert (tmp_path / "run" / ".lock").read_text() == f"{os.getpid()} training\n"
        with (
            pytest.raises(
                DirectoryInUseError, match=f"another process \\(PID {os.getpid()}\\) is training"
            ),
            directory_lock(tmp_path / "run", "training"),
        ):
            pytest.fail("a second lock must be refused")
    with directory_lock(tmp_path / "run", "training"):  # released on exit
        pass


def test_the_lock_of_a_killed_process_does_not_block(tmp_path: Path) -> None:
    ready_read, ready_write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child holds the lock until it is killed
        try:
            with directory_lock(tmp_path, "collecting a dataset"):
                os.write(ready_write, b"x")
                signal.pause()
        finally:
            os._exit(1)
    try:
        assert os.read(ready_read, 1) == b"x"
        busy = f"PID {pid}\\) is collecting a dataset there.*kill {pid}"
        with pytest.raises(DirectoryInUseError, match=busy), directory_lock(tmp_path, "training"):
            pass
    finally:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        os.close(ready_read)
        os.close(ready_write)
    with directory_lock(tmp_path, "training"):
        assert (tmp_path / ".lock").read_text() == f"{os.getpid()} training\n"
