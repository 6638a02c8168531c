"""Atomic file writes (temporary file, fsync, rename), directory locks and safe checkpoint loading.

Every file kinet_rl writes goes through :func:`atomic_write`, so an interrupted job or a full
disk never leaves a half-written checkpoint, dataset marker, image or report behind; a job that
writes into a directory holds its :func:`directory_lock`, so a second job cannot write there too.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import pickle
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import torch

#: Name of the lock file that :func:`directory_lock` holds in a directory.
LOCK_FILE = ".lock"
#: ``errno`` values of a full disk or an exhausted quota.
DISK_FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT)


class CheckpointError(RuntimeError):
    """A checkpoint is missing, corrupt, truncated or does not match what the caller expects."""


class DiskFullError(OSError):
    """A write failed for lack of disk space (or quota); the previous version of the file is kept."""


class DirectoryInUseError(RuntimeError):
    """Another live process holds the directory's lock (it is collecting or training there)."""


def disk_full(path: Path, err: OSError) -> DiskFullError:
    """The :class:`DiskFullError` for a failed write of ``path``."""
    return DiskFullError(
        err.errno,
        f"Cannot write {path}: no space left on the device (or the disk quota is exhausted). "
        f"Nothing was half-written: {path.name} keeps its previous complete version, if it had "
        f"one. Free disk space under {path.parent} (or write elsewhere), then run the same "
        "command again to resume.",
    )


@contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "wb") -> Iterator[IO[Any]]:
    """Opens a temporary file beside ``path``; on success syncs it and renames it over ``path``.

    Raises:
        DiskFullError: The disk filled up; ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, mode) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as err:
        if err.errno in DISK_FULL_ERRNOS:
            raise disk_full(path, err) from err
        raise
    finally:
        tmp.unlink(missing_ok=True)
    dir_fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


@contextmanager
def directory_lock(path: str | os.PathLike, activity: str) -> Iterator[Path]:
    """Holds an exclusive lock on ``<path>/.lock`` for the block; yields the directory.

    The lock is an ``fcntl.flock`` that the kernel releases when the holder exits, even killed,
    so a lock left by a dead process never blocks. The file names the holder's PID and activity,
    for the error that a second process gets.

    Args:
        path: The directory (created if missing).
        activity: What this process does there (e.g. ``"collecting a dataset"``).

    Raises:
        DirectoryInUseError: Another process holds the lock.
    """
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    fd = os.open(path / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 4096, 0).decode(errors="replace").split(maxsplit=1)
            pid = holder[0] if holder else "unknown"
            doing = holder[1].strip() if len(holder) > 1 else "writing"
            raise DirectoryInUseError(
                f"{path} is in use: another process (PID {pid}) is {doing} there, and a "
                "second writer would corrupt its files. Wait for that process to finish (or "
                f"stop it, e.g. kill {pid}), or use another directory."
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()} {activity}\n".encode(), 0)
        yield path
    finally:
        os.close(fd)  # releases the lock


def wait_for_directory(path: str | os.PathLike) -> None:
    """Blocks until no process holds :func:`directory_lock` on ``path`` (returns at once if none
    does)."""
    lock = Path(path) / LOCK_FILE
    if not lock.exists():
        return
    fd = os.open(lock, os.O_RDWR)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)  # waits for the holder
    finally:
        os.close(fd)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Writes ``text`` atomically."""
    with atomic_write(path, "w") as f:
        f.write(text)


def atomic_write_json(path: str | os.PathLike, payload: Mapping[str, Any]) -> None:
    """Writes ``payload`` as indented, key-sorted JSON atomically."""
    atomic_write_text(path, json.dumps(payload, indent=2, sort_keys=True))


def atomic_save_with(path: str | os.PathLike, write: Callable[[IO[bytes]], None]) -> Path:
    """Calls ``write(file)`` on a temporary binary file, then renames it over ``path``."""
    with atomic_write(path, "wb") as f:
        write(f)
    return Path(path)


def atomic_torch_save(obj: Any, path: str | os.PathLike) -> None:
    """``torch.save`` to ``path`` atomically."""
    atomic_save_with(path, lambda f: torch.save(obj, f))


def _corrupt(path: Path, err: Exception) -> CheckpointError:
    return CheckpointError(
        f"Checkpoint {path} is corrupt or truncated and could not be read safely "
        f"({type(err).__name__} from torch.load with weights_only=True); delete it (a training run then starts afresh) or point to "
        "another checkpoint."
    )


def safe_torch_load(
    path: str | os.PathLike, required: tuple[str, ...] = (), writer: str = "kinet_rl"
) -> dict[str, Any]:
    """Loads a checkpoint dict with ``weights_only=True``, turning every failure into a clear error.

    Args:
        path: Checkpoint file.
        required: Top-level entries the dict must hold.
        writer: What writes such files, named in the error for a foreign file.

    Raises:
        CheckpointError: Missing, corrupt, truncated or foreign file.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(
            f"No checkpoint file at {path}; check the path or train a model first."
        )
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:
        if "Unsupported global" not in str(err):  # garbage bytes, not a foreign object
            raise _corrupt(path, err) from None
        raise CheckpointError(  # objects that weights_only=True refuses to build
            f"Checkpoint {path} holds Python objects that cannot be loaded safely (kinet_rl "
            "loads checkpoints with weights_only=True and never runs code from a file); it was "
            "not written by kinet_rl or it was altered. Re-create it with save_checkpoint from a "
            "trusted source, or delete it (a training run then starts afresh)."
        ) from None
    except Exception as err:  # torch raises several types for truncated or corrupt files
        raise _corrupt(path, err) from None
    if not isinstance(state, dict) or any(key not in state for key in required):
        raise CheckpointError(
            f"Checkpoint {path} lacks the entries {list(required)}; it was not written by {writer}."
        )
    return state
