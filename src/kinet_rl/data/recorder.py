"""Recording a robot's pushes in the plain push folder format (:mod:`kinet_rl.data.push_folder`)
from its control loop: :class:`PushRecorder`, atomic and resumable after a crash."""

from __future__ import annotations

import logging
import os
import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from kinet_rl.atomic import atomic_save_with, atomic_write_json, atomic_write_text
from kinet_rl.data.push_folder import (
    EPISODE_PATTERN,
    META_FILE,
    PUSH_COLUMNS,
    PUSHES_CSV,
    RECORDING_DIR,
    WORKSPACE_TOLERANCE,
    ActionWidthError,
    FolderMeta,
    FrameSizeError,
    NonFiniteActionError,
    NotPushFolderError,
    OutsideWorkspaceError,
    ShortEpisodeError,
    episode_name,
    frame_files,
    frame_name,
)

logger = logging.getLogger(__name__)


def _frame_array(frame: np.ndarray | torch.Tensor) -> np.ndarray:
    """An RGB uint8 ``[H, W, 3]`` array of a frame, or a ValueError saying what it is."""
    array = frame.cpu().numpy() if isinstance(frame, torch.Tensor) else np.asarray(frame)
    if array.ndim != 3 or array.shape[-1] != 3 or array.dtype != np.uint8:
        raise ValueError(
            f"A frame must be an RGB uint8 array [H, W, 3], got {array.dtype} {array.shape}."
        )
    return array


class PushRecorder:
    """Records a robot's pushes in the plain folder format, one step at a time; crash-safe.

    Each :meth:`append` stores the frame the robot saw and the push it then made; :meth:`close_episode`
    stores the last frame (no push after it) and publishes the episode under its final name with
    one atomic rename, so a reader never sees half an episode. Frames are written atomically,
    each push row is synced before :meth:`append` returns.

    After a crash, a new recorder on the same folder recovers the interrupted episode: it keeps
    its frames with the pushes between them (the push after its last stored frame is dropped, as
    the frame after that push was never stored) and closes it, or discards it when fewer than 2
    frames were stored; then recording goes on with the next episode.

    Example:
        >>> recorder = PushRecorder("pushes/", workspace_half_size=0.25, camera="top")
        >>> for _ in range(10):  # doctest: +SKIP
        ...     frame = camera.read()
        ...     push = choose_push(frame)  # (start x, start y, end x, end y), metres
        ...     robot.push(push)
        ...     recorder.append(frame, push)
        >>> recorder.close_episode(camera.read())  # doctest: +SKIP

    Args:
        root: The push folder (created if missing).
        workspace_half_size: Half the side of the square workspace, metres.
        units: ``"metres"`` (pushes in the table frame) or ``"normalised"`` (divided by the half
            size).
        camera: The camera's name, recorded in ``meta.json``.

    Raises:
        NotPushFolderError: ``root`` is a push folder of another workspace, units or camera.
    """

    def __init__(
        self,
        root: str | os.PathLike,
        workspace_half_size: float,
        units: str = "metres",
        camera: str | None = None,
    ) -> None:
        self.root = Path(root)
        meta = FolderMeta(float(workspace_half_size), units, None, camera)
        if (self.root / META_FILE).exists():
            stored = FolderMeta.read(self.root)
            if (stored.workspace_half_size, stored.units, stored.camera) != (
                meta.workspace_half_size,
                meta.units,
                meta.camera,
            ):
                raise NotPushFolderError(
                    f"{self.root} records workspace_half_size={stored.workspace_half_size}, "
                    f"units={stored.units!r}, camera={stored.camera!r}, not "
                    f"{meta.workspace_half_size}, {meta.units!r}, {meta.camera!r}; record "
                    "into another folder."
                )
            meta = stored
        else:
            self.root.mkdir(parents=True, exist_ok=True)
            atomic_write_json(self.root / META_FILE, meta.as_json())
        self.meta = meta
        self._open = self.root / RECORDING_DIR
        self._frames = 0
        if self._open.exists():
            self._recover()

    @property
    def num_episodes(self) -> int:
        """Closed episodes in the folder."""
        return len(self._closed())

    @property
    def open_frames(self) -> int:
        """Frames stored in the open episode so far."""
        return self._frames

    def _closed(self) -> list[Path]:
        return [p for p in self.root.iterdir() if EPISODE_PATTERN.fullmatch(p.name) and p.is_dir()]

    def _next_name(self) -> str:
        indices = [int(EPISODE_PATTERN.fullmatch(p.name).group(1)) for p in self._closed()]  # type: ignore[union-attr]
        return episode_name(max(indices, default=-1) + 1)

    def _check_push(self, push: Sequence[float] | np.ndarray | torch.Tensor) -> np.ndarray:
        values = np.asarray(push.cpu() if isinstance(push, torch.Tensor) else push, np.float64)
        if values.shape != (4,):
            raise ActionWidthError(
                f"A push is 4 numbers ({', '.join(PUSH_COLUMNS)}), got shape {values.shape}."
            )
        if not np.isfinite(values).all():
            raise NonFiniteActionError(f"A push holds NaN or infinite numbers: {values.tolist()}.")
        if (np.abs(self.meta.normalise(values)) > 1 + WORKSPACE_TOLERANCE).any():
            raise OutsideWorkspaceError(
                f"The push {values.tolist()} ({self.meta.units}) leaves the workspace of half "
                f"size {self.meta.workspace_half_size} m."
            )
        return values

    def _check_frame(self, frame: np.ndarray | torch.Tensor) -> np.ndarray:
        array = _frame_array(frame)
        size = (array.shape[1], array.shape[0])
        if self.meta.image_size is None:
            self.meta = FolderMeta(
                self.meta.workspace_half_size, self.meta.units, size, self.meta.camera
            )
            atomic_write_json(self.root / META_FILE, self.meta.as_json())
        elif size != tuple(self.meta.image_size):
            raise FrameSizeError(
                f"The frame is {size[0]}x{size[1]} px but the folder's frames are "
                f"{self.meta.image_size[0]}x{self.meta.image_size[1]} px."
            )
        return array

    def _write_frame(self, array: np.ndarray) -> None:
        self._open.mkdir(exist_ok=True)
        path = self._open / frame_name(self._frames)
        atomic_save_with(path, lambda f: Image.fromarray(array).save(f, format="PNG"))
        self._frames += 1

    def append(
        self, frame: np.ndarray | torch.Tensor, push: Sequence[float] | np.ndarray | torch.Tensor
    ) -> None:
        """Stores ``frame`` (RGB uint8 ``[H, W, 3]``) and the ``push`` made after it (start x, y,
        end x, y in the folder's units). Both are checked before anything is written.

        Raises:
            ActionWidthError, NonFiniteActionError, OutsideWorkspaceError, FrameSizeError,
            ValueError: A bad push or frame (nothing written).
        """
        values = self._check_push(push)
        array = self._check_frame(frame)
        self._write_frame(array)
        csv_path = self._open / PUSHES_CSV
        with open(csv_path, "a", newline="") as f:
            if f.tell() == 0:
                f.write(",".join(PUSH_COLUMNS) + "\n")
            f.write(",".join(repr(float(v)) for v in values) + "\n")
            f.flush()
            os.fsync(f.fileno())

    def close_episode(self, last_frame: np.ndarray | torch.Tensor) -> Path:
        """Stores the episode's last frame (no push after it) and publishes the episode.

        Returns:
            The episode's folder.

        Raises:
            ShortEpisodeError: No push was appended in this episode.
        """
        if self._frames == 0:
            raise ShortEpisodeError(
                "close_episode() with no appended push: an episode needs a frame, a push and "
                "the frame after it."
            )
        self._write_frame(self._check_frame(last_frame))
        return self._publish()

    def discard_episode(self) -> None:
        """Drops the open episode's frames and pushes."""
        shutil.rmtree(self._open, ignore_errors=True)
        self._frames = 0

    def _publish(self) -> Path:
        target = self.root / self._next_name()
        os.rename(self._open, target)
        dir_fd = os.open(self.root, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)
        self._frames = 0
        logger.info("Recorded %s.", target)
        return target

    def _recover(self) -> None:
        """Closes (or discards) the episode a crash interrupted; see the class docstring."""
        for tmp in self._open.glob(".*.tmp"):
            tmp.unlink()
        frames = len(frame_files(self._open))
        rows: list[str] = []
        csv_path = self._open / PUSHES_CSV
        if csv_path.exists():
            text = csv_path.read_text()
            lines = text.split("\n")[1:-1]  # complete rows only: the last may be cut short
            rows = [line for line in lines if line.count(",") == len(PUSH_COLUMNS) - 1]
        steps = min(frames, len(rows))  # frame k, then push k: a step is both
        if steps < 2:
            logger.warning(
                "Discarding the episode a crash interrupted in %s (%d complete step(s)).",
                self._open,
                steps,
            )
            self.discard_episode()
            return
        for index in range(steps, frames):
            (self._open / frame_name(index)).unlink()
        header = ",".join(PUSH_COLUMNS)
        atomic_write_text(csv_path, "\n".join([header, *rows[: steps - 1]]) + "\n")
        self._frames = steps
        target = self._publish()
        logger.warning(
            "Recovered the episode a crash interrupted as %s: %d frames, %d pushes (the push "
            "after its last stored frame is dropped).",
            target,
            steps,
            steps - 1,
        )
