"""LeRobot dataset format v3.0: its layout and constants, its errors, and the reader.

The writer is :mod:`kinet_rl.data.lerobot_writer` (``export_lerobot``), the video storage
:mod:`kinet_rl.data.lerobot_video`; all three are ours, on pyarrow and PyAV (the optional extra
``lerobot``), not on the ``lerobot`` package (which pins another torch). The camera is stored as
PNG images in the Parquet files (dtype ``image``, bit-exact) or as AV1 MP4 videos (dtype
``video``, lossy). What we write and read (docs/data.md, "LeRobot v3")::

    <out>/
      meta/info.json                      codebase_version "v3.0", fps, features, paths, totals,
                                          and "kinet_rl": {"workspace_half_size": metres, ...}
      meta/stats.json                     min, max, mean, std, count per numeric feature and image
      meta/tasks.parquet                  task_index, task (one task: "push the objects")
      meta/episodes/chunk-000/file-000.parquet
                                          episode_index, tasks, length, data/chunk_index,
                                          data/file_index, dataset_from_index, dataset_to_index,
                                          meta/episodes/chunk_index, meta/episodes/file_index,
                                          [videos/<camera>/chunk_index, file_index,
                                           from_timestamp, to_timestamp]
      data/chunk-CCC/file-FFF.parquet     one row per frame: [<camera> {bytes: PNG, path: null}],
                                          action float32[4] (metres, table frame), action_is_pad,
                                          [observation.state.object_pos float32[2N],
                                           observation.state.object_yaw float32[N]],
                                          timestamp, frame_index, episode_index, index, task_index
      [videos/<camera>/chunk-CCC/file-FFF.mp4]
                                          with ``video=True``: the frames, episodes back to back

**Pad convention:** frame ``t``'s ``action`` is the push made after frame ``t``; an episode's last
frame has none, so its ``action`` is zeros and ``action_is_pad`` is true. The reader drops each
episode's last action (padded or not): N frames give N - 1 pushes.
"""

from __future__ import annotations

import io
import json
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from PIL import Image

from kinet_rl.data.lerobot_video import (
    INSTALL_HINT,
    LeRobotError,
    MissingVideoError,  # noqa: F401 (re-exported: the reader raises it)
    VideoFrameError,  # noqa: F401 (re-exported: the reader raises it)
    VideoFrames,
    check_videos,
    episode_clips,
    require_av,
)
from kinet_rl.data.push_folder import (
    UNITS,
    WORKSPACE_TOLERANCE,
    ActionWidthError,
    FolderEpisode,
    FolderMeta,
    FrameCountError,
    FrameSizeError,
    NonFiniteActionError,
    OutsideWorkspaceError,
    PushFolder,
    ShortEpisodeError,
    frame_name,
)
from kinet_rl.keys import OBJECT_POS, OBJECT_YAW

CODEBASE_VERSION = "v3.0"
INFO_FILE = Path("meta") / "info.json"
DEFAULT_CAMERA = "observation.images.top"
DEFAULT_ACTION = "action"
PAD_KEY = "action_is_pad"
#: info.json entry with what kinet_rl adds (the workspace half size, metres).
EXTRA_KEY = "kinet_rl"
STATE_KEYS = {
    OBJECT_POS: "observation.state.object_pos",
    OBJECT_YAW: "observation.state.object_yaw",
}
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
EPISODES_PATH = "meta/episodes/chunk-000/file-000.parquet"
TASK = "push the objects"
DEFAULT_FPS = 10
#: LeRobot's defaults (``lerobot/datasets/utils.py``).
CHUNKS_SIZE, DATA_FILES_SIZE_IN_MB, VIDEO_FILES_SIZE_IN_MB = 1000, 100, 200


class NotLeRobotDatasetError(LeRobotError):
    """The folder has no (readable) ``meta/info.json``."""


class LeRobotVersionError(LeRobotError):
    """``meta/info.json`` states a ``codebase_version`` other than v3.0."""


class MissingFeatureError(LeRobotError):
    """The camera or action key is not a feature of the dataset (or not an image or video)."""


class MissingWorkspaceError(LeRobotError):
    """No workspace half size: not in ``info.json`` and not given."""


class TargetNotEmptyError(LeRobotError):
    """The export's target folder exists and is not empty."""


def require_pyarrow() -> Any:
    """``(pyarrow, pyarrow.parquet)``, or an ``ImportError`` naming the extra."""
    try:
        import pyarrow as pa
        import pyarrow.compute  # noqa: F401  (pa.compute)
        import pyarrow.parquet as pq
    except ImportError as err:  # pragma: no cover - the extra is installed in CI
        raise ImportError(f"LeRobot datasets need pyarrow: {INSTALL_HINT}") from err
    return pa, pq


@dataclass(frozen=True)
class LeRobotEpisode:
    """One episode read back: ``frames`` uint8 ``[N, H, W, 3]``, ``pushes`` ``[N - 1, 4]``
    metres (table frame), and the dataset's ``workspace_half_size`` (metres)."""

    index: int
    frames: np.ndarray
    pushes: np.ndarray
    workspace_half_size: float


class _FrameStore(Protocol):
    def frames(self, position: int, start: int, stop: int) -> list[Image.Image]:
        """Frames ``start:stop`` of the episode at ``position``, as RGB images."""
        ...


class _PngFrames:
    """An ``image`` camera's frames: PNG bytes from the Parquet files, decoded when asked."""

    def __init__(
        self, root: Path, images: list[bytes], bounds: list[tuple[int, int, int]], size: Any
    ) -> None:
        self._root, self._images, self._bounds, self._size = root, images, bounds, size

    def frames(self, position: int, start: int, stop: int) -> list[Image.Image]:
        index, first, end = self._bounds[position]
        out = []
        for data in self._images[first + start : min(first + stop, end)]:
            with Image.open(io.BytesIO(data)) as image:
                if image.size != self._size:
                    raise FrameSizeError(
                        f"Episode {index} of {self._root}: a frame is {image.size[0]}x"
                        f"{image.size[1]} px, the first {self._size[0]}x{self._size[1]} px."
                    )
                out.append(image.convert("RGB"))
        return out


@dataclass(frozen=True)
class _ImportedEpisode(FolderEpisode):
    """A LeRobot episode as the importer sees a push folder's: ``frames`` are names only
    (``<folder>/episode_<i>/frame_<t>.png``); the pixels come from ``store`` when loaded."""

    store: _FrameStore | None = field(default=None, compare=False, repr=False)
    position: int = 0

    def load_frames(self, start: int, stop: int) -> list[Image.Image]:
        assert self.store is not None
        return self.store.frames(self.position, start, stop)


class LeRobotSource:
    """A checked LeRobot v3.0 dataset (see :func:`read_lerobot`); iterate for its episodes."""

    def __init__(
        self,
        root: Path,
        camera_key: str,
        workspace_half_size: float,
        store: _FrameStore,
        actions: np.ndarray,
        bounds: list[tuple[int, int, int]],
        image_size: tuple[int, int],
    ) -> None:
        self.root, self.camera_key = root, camera_key
        self.workspace_half_size = workspace_half_size
        self._store, self._actions, self._bounds = store, actions, bounds
        self.image_size = image_size  # (width, height)

    def __len__(self) -> int:
        return len(self._bounds)

    def __iter__(self) -> Iterator[LeRobotEpisode]:
        for position, (index, start, stop) in enumerate(self._bounds):
            frames = self._store.frames(position, 0, stop - start)
            yield LeRobotEpisode(
                index,
                np.stack([np.asarray(frame) for frame in frames]),
                self._actions[start : stop - 1].astype(np.float64),
                self.workspace_half_size,
            )

    def as_push_folder(self) -> PushFolder:
        """The episodes as a checked :class:`PushFolder` (pushes normalised), for
        :func:`kinet_rl.data.importing.plan_import`; frames are decoded when imported."""
        half = self.workspace_half_size
        meta = FolderMeta(half, "metres", self.image_size, self.camera_key)
        episodes = []
        for position, (index, start, stop) in enumerate(self._bounds):
            folder = self.root / f"episode_{index:06d}"
            pushes = self._actions[start : stop - 1].astype(np.float64) / half
            episodes.append(
                _ImportedEpisode(
                    folder,
                    tuple(folder / frame_name(t) for t in range(stop - start)),
                    pushes.astype(np.float32),
                    self.image_size,
                    self._store,
                    position,
                )
            )
        return PushFolder(self.root, meta, tuple(episodes))


def is_lerobot_folder(folder: str | os.PathLike) -> bool:
    """Whether ``folder`` looks like a LeRobot dataset (it has ``meta/info.json``)."""
    return (Path(folder) / INFO_FILE).is_file()


def read_lerobot(
    folder: str | os.PathLike,
    camera_key: str = DEFAULT_CAMERA,
    action_key: str = DEFAULT_ACTION,
    workspace_half_size: float | None = None,
    action_units: str | None = None,
) -> LeRobotSource:
    """Reads and checks a LeRobot v3.0 dataset of camera frames and 4-d pushes.

    Every check runs here, before any frame is decoded (a video camera's files are demuxed to
    check that each episode's frames are there, once). Episodes are ordered by
    ``episode_index``, their frames by ``frame_index``; the last action of each is dropped.

    Args:
        folder: The dataset folder (``meta/info.json``, ``data/``, ``videos/`` for a video).
        camera_key: The camera feature: dtype ``image`` (PNG in the Parquet files) or ``video``
            (MP4 files that PyAV decodes, e.g. LeRobot's AV1).
        action_key: The action feature: 4 numbers, start and end point (table frame).
        workspace_half_size: Metres; needed when ``info.json`` has no
            ``kinet_rl.workspace_half_size``.
        action_units: ``"metres"`` or ``"normalised"`` (metres / ``workspace_half_size``, in
            ``[-1, 1]``); default ``info.json``'s ``kinet_rl.action_units``, else metres.

    Raises:
        NotLeRobotDatasetError, LeRobotVersionError, MissingFeatureError, MissingWorkspaceError,
        ActionWidthError, NonFiniteActionError, OutsideWorkspaceError, ShortEpisodeError,
        FrameCountError, MissingVideoError, VideoFrameError, FrameSizeError: What is wrong, by
        name.
        ImportError: pyarrow, or for a video camera PyAV, is not installed.
    """
    root = Path(folder)
    info_path = root / INFO_FILE
    if not info_path.is_file():
        raise NotLeRobotDatasetError(
            f"{root} is not a LeRobot dataset: it has no {INFO_FILE} (docs/data.md, 'LeRobot v3')."
        )
    try:
        info = json.loads(info_path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise NotLeRobotDatasetError(f"Cannot read {info_path} ({err}).") from err
    if not isinstance(info, dict) or not isinstance(info.get("features"), dict):
        raise NotLeRobotDatasetError(f"{info_path} has no 'features' object.")
    version = info.get("codebase_version")
    if version != CODEBASE_VERSION:
        raise LeRobotVersionError(
            f"{info_path} states codebase_version {version!r}; this reader takes "
            f"{CODEBASE_VERSION!r}. Convert it with LeRobot's v3.0 conversion script first."
        )
    features = info["features"]
    if camera_key not in features:
        cameras = sorted(k for k, v in features.items() if v.get("dtype") in ("image", "video"))
        raise MissingFeatureError(
            f"{info_path} has no feature {camera_key!r}; its cameras: {cameras}. Pass --camera-key."
        )
    if features[camera_key].get("dtype") not in ("image", "video"):
        raise MissingFeatureError(
            f"{camera_key!r} is a {features[camera_key].get('dtype')!r} feature, not a camera "
            "('image' or 'video')."
        )
    video = features[camera_key]["dtype"] == "video"
    fps, video_path = _video_settings(info, info_path) if video else (0.0, "")
    if action_key not in features:
        raise MissingFeatureError(
            f"{info_path} has no feature {action_key!r}; its features: {sorted(features)}. Pass "
            "--action-key."
        )
    shape = list(features[action_key].get("shape") or [])
    if shape != [4]:
        raise ActionWidthError(
            f"{action_key!r} has shape {shape} in {info_path}; a push is 4 numbers (start_x, "
            "start_y, end_x, end_y, metres)."
        )
    extra = info.get(EXTRA_KEY)
    extra = extra if isinstance(extra, dict) else {}
    half = workspace_half_size or extra.get("workspace_half_size")
    if half is None or not 0 < float(half) < math.inf:
        raise MissingWorkspaceError(
            f"{info_path} records no {EXTRA_KEY}.workspace_half_size; pass "
            "--workspace-half-size <metres> (half the side of the square workspace)."
        )
    half = float(half)
    units = action_units or extra.get("action_units", "metres")
    if units not in UNITS:
        raise LeRobotError(
            f"Action units {units!r} ({info_path} or --action-units); use one of {list(UNITS)}."
        )
    pa, pq = require_pyarrow()
    if video:
        require_av()  # before any work
    files = sorted((root / "data").glob("chunk-*/file-*.parquet"))
    if not files:
        raise NotLeRobotDatasetError(f"{root / 'data'} holds no chunk-*/file-*.parquet files.")
    wanted = [action_key, "episode_index", "frame_index"]
    if not video:
        wanted.append(camera_key)
    elif "timestamp" in pq.read_schema(files[0]).names:
        wanted.append("timestamp")
    table = pa.concat_tables([pq.read_table(f, columns=wanted) for f in files])
    action_column = table.column(action_key).combine_chunks()
    lengths = np.asarray(pa.compute.list_value_length(action_column))
    if len(lengths) and (lengths != 4).any():
        raise ActionWidthError(
            f"{action_key!r} holds rows of {sorted(set(lengths.tolist()))} numbers; a push is 4."
        )
    actions = np.asarray(action_column.flatten(), dtype=np.float64).reshape(-1, 4)
    if units == "normalised":
        actions = actions * half  # metres from here on
    episode_index = np.asarray(table.column("episode_index"), dtype=np.int64)
    frame_index = np.asarray(table.column("frame_index"), dtype=np.int64)
    order = np.lexsort((frame_index, episode_index))
    actions, episode_index = actions[order], episode_index[order]
    bounds: list[tuple[int, int, int]] = []
    indices, starts = np.unique(episode_index, return_index=True)
    stops = [*starts[1:].tolist(), len(episode_index)]
    for index, start, stop in zip(indices.tolist(), starts.tolist(), stops, strict=True):
        if stop - start < 2:
            raise ShortEpisodeError(f"Episode {index} of {root} holds {stop - start} frame(s).")
        frames = frame_index[order][start:stop]
        if (frames != np.arange(stop - start)).any():
            raise FrameCountError(f"Episode {index} of {root}: frame_index is not 0, 1, ...")
        pushes = actions[start : stop - 1]
        if not np.isfinite(pushes).all():
            raise NonFiniteActionError(f"Episode {index} of {root} holds NaN or infinite pushes.")
        if (np.abs(pushes) > half * (1 + WORKSPACE_TOLERANCE)).any():
            raise OutsideWorkspaceError(
                f"Episode {index} of {root} holds pushes beyond the workspace (+-{half} m); "
                f"check --workspace-half-size and the action's units ({units})."
            )
        bounds.append((int(index), start, stop))
    cam_shape = features[camera_key].get("shape") or []
    store: _FrameStore
    if video:
        timestamps = (
            np.asarray(table.column("timestamp"), dtype=np.float64)[order]
            if "timestamp" in wanted
            else frame_index[order] / fps
        )
        clips = episode_clips(
            root,
            video_path,
            camera_key,
            [(index, timestamps[start:stop]) for index, start, stop in bounds],
        )
        size = check_videos(clips, fps)
        store = VideoFrames(clips, fps)
    else:
        images = _images(root, table.column(camera_key).to_pylist(), order, camera_key)
        with Image.open(io.BytesIO(images[0])) as first:
            size = first.size
        store = _PngFrames(root, images, bounds, size)
    if len(cam_shape) == 3 and tuple(cam_shape[:2]) != (size[1], size[0]):
        raise NotLeRobotDatasetError(
            f"{camera_key!r}: info.json states shape {cam_shape}, the first frame is "
            f"{size[0]}x{size[1]} px."
        )
    return LeRobotSource(root, camera_key, half, store, actions, bounds, size)


def _video_settings(info: dict[str, Any], info_path: Path) -> tuple[float, str]:
    """A video camera's frame rate and ``video_path`` template, from ``info.json``."""
    fps, template = info.get("fps"), info.get("video_path")
    if (
        isinstance(fps, bool)
        or not isinstance(fps, (int, float))
        or not 0 < fps < math.inf
        or not isinstance(template, str)
    ):
        raise NotLeRobotDatasetError(
            f"{info_path}: a video camera needs 'fps' (> 0) and a 'video_path' template; it "
            f"states {fps!r} and {template!r}."
        )
    return float(fps), template


def _images(root: Path, cells: list[Any], order: np.ndarray, camera_key: str) -> list[bytes]:
    """An ``image`` column's PNG bytes (embedded, or from the file a cell's ``path`` names),
    in ``order``."""
    images: list[bytes] = []
    for row in order.tolist():
        cell = cells[row]
        data = cell.get("bytes") if isinstance(cell, dict) else None
        if data is None and isinstance(cell, dict) and cell.get("path"):
            data = (root / cell["path"]).read_bytes()
        if data is None:
            raise NotLeRobotDatasetError(f"Frame {row} of {camera_key!r} holds no image bytes.")
        images.append(data)
    return images
