"""LeRobot dataset format v3.0 (images only): export a kinet_rl dataset, read one for import.

Written here on pyarrow (the optional extra ``lerobot``), not on the ``lerobot`` package (which
pins another torch). What we write (docs/data.md, "LeRobot v3")::

    <out>/
      meta/info.json                      codebase_version "v3.0", fps, features, paths, totals,
                                          and "kinet_rl": {"workspace_half_size": metres, ...}
      meta/stats.json                     min, max, mean, std, count per numeric feature and image
      meta/tasks.parquet                  task_index, task (one task: "push the objects")
      meta/episodes/chunk-000/file-000.parquet
                                          episode_index, tasks, length, data/chunk_index,
                                          data/file_index, dataset_from_index, dataset_to_index,
                                          meta/episodes/chunk_index, meta/episodes/file_index
      data/chunk-000/file-000.parquet     one row per frame: <camera> {bytes: PNG, path: null},
                                          action float32[4] (metres, table frame), action_is_pad,
                                          [observation.state.object_pos float32[2N],
                                           observation.state.object_yaw float32[N]],
                                          timestamp, frame_index, episode_index, index, task_index

**Pad convention:** frame ``t``'s ``action`` is the push made after frame ``t``; an episode's last
frame has none, so its ``action`` is zeros and ``action_is_pad`` is true. The reader drops each
episode's last action (padded or not): N frames give N - 1 pushes.
"""

from __future__ import annotations

import io
import json
import math
import os
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from kinet_rl.data.push_folder import (
    WORKSPACE_TOLERANCE,
    ActionWidthError,
    FolderEpisode,
    FolderMeta,
    FrameCountError,
    FrameSizeError,
    NonFiniteActionError,
    OutsideWorkspaceError,
    PushFolder,
    PushFolderError,
    ShortEpisodeError,
    frame_name,
)
from kinet_rl.data.storage import METADATA_FILE, open_episodes, read_json
from kinet_rl.keys import ACTION, OBJECT_POS, OBJECT_YAW, PIXELS

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
INSTALL_HINT = "pip install 'kinet_rl[lerobot]' (pyarrow)"


class LeRobotError(PushFolderError):
    """A LeRobot dataset cannot be read or written; the message names the fix."""


class NotLeRobotDatasetError(LeRobotError):
    """The folder has no (readable) ``meta/info.json``."""


class LeRobotVersionError(LeRobotError):
    """``meta/info.json`` states a ``codebase_version`` other than v3.0."""


class MissingFeatureError(LeRobotError):
    """The camera or action key is not a feature of the dataset (or the camera is a video)."""


class MissingWorkspaceError(LeRobotError):
    """No workspace half size: not in ``info.json`` and not given."""


class TargetNotEmptyError(LeRobotError):
    """The export's target folder exists and is not empty."""


def _pyarrow() -> Any:
    try:
        import pyarrow as pa
        import pyarrow.compute  # noqa: F401  (pa.compute)
        import pyarrow.parquet as pq
    except ImportError as err:  # pragma: no cover - the extra is installed in CI
        raise ImportError(f"LeRobot datasets need pyarrow: {INSTALL_HINT}") from err
    return pa, pq


def _png(frame: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(frame).save(buffer, format="PNG")
    return buffer.getvalue()


def _stats(values: np.ndarray, axis: tuple[int, ...] = (0,)) -> dict[str, Any]:
    return {
        "min": np.nanmin(values, axis=axis).tolist(),
        "max": np.nanmax(values, axis=axis).tolist(),
        "mean": np.nanmean(values, axis=axis).tolist(),
        "std": np.nanstd(values, axis=axis).tolist(),
        "count": [int(values.shape[0])],
    }


def export_lerobot(
    dataset_path: str | os.PathLike,
    out_dir: str | os.PathLike,
    camera: str = DEFAULT_CAMERA,
    include_object_state: bool = True,
    fps: int = DEFAULT_FPS,
) -> Path:
    """Writes the complete kinet_rl dataset ``dataset_path`` (all splits, in stored order) as a
    LeRobot v3.0 dataset at ``out_dir`` (see the module docstring), atomically: into a temporary
    folder beside it, renamed at the end.

    Args:
        dataset_path: A complete dataset folder (``metadata.json``).
        out_dir: The new folder; must not exist or be empty.
        camera: The image feature's key.
        include_object_state: Also write the object positions and yaws, where stored.
        fps: Frames per second stated in ``info.json`` (kinet_rl's pushes have no clock).

    Returns:
        ``out_dir``.

    Raises:
        TargetNotEmptyError: ``out_dir`` exists and is not empty (nothing written).
        DatasetError: The dataset is missing, partial or corrupt.
    """
    pa, pq = _pyarrow()
    source, out = Path(dataset_path), Path(out_dir)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise TargetNotEmptyError(f"{out} exists and is not empty; choose a new folder.")
    metadata = read_json(source / METADATA_FILE)
    half = metadata.get("workspace_half_size")
    if half is None:
        raise MissingWorkspaceError(f"{source / METADATA_FILE} records no workspace_half_size.")
    half = float(half)
    episodes = open_episodes(source)
    pixels = episodes[PIXELS]  # uint8 [E, T + 1, H, W, 3]
    action = episodes[ACTION].numpy().astype(np.float64) * half  # [E, T, 4] metres
    num_episodes, frames = pixels.shape[0], pixels.shape[1]
    height, width = int(pixels.shape[2]), int(pixels.shape[3])
    states = {
        key: episodes[key].numpy().reshape(num_episodes, frames, -1).astype(np.float32)
        for key in STATE_KEYS
        if include_object_state and key in episodes.keys()  # noqa: SIM118 (a TensorDict)
    }
    rows = num_episodes * frames
    pad = np.zeros((num_episodes, frames), dtype=bool)
    pad[:, -1] = True
    actions = np.zeros((num_episodes, frames, 4), dtype=np.float32)
    actions[:, :-1] = action
    images = [_png(frame) for frame in pixels.reshape(rows, height, width, 3).numpy()]
    episode_index = np.repeat(np.arange(num_episodes, dtype=np.int64), frames)
    frame_index = np.tile(np.arange(frames, dtype=np.int64), num_episodes)
    columns: dict[str, Any] = {
        camera: pa.array(
            [{"bytes": b, "path": None} for b in images],
            type=pa.struct([("bytes", pa.binary()), ("path", pa.string())]),
        ),
        DEFAULT_ACTION: pa.FixedSizeListArray.from_arrays(pa.array(actions.reshape(-1)), 4),
        PAD_KEY: pa.array(pad.reshape(-1)),
    }
    features: dict[str, Any] = {
        camera: {
            "dtype": "image",
            "shape": [height, width, 3],
            "names": ["height", "width", "channels"],
        },
        DEFAULT_ACTION: {
            "dtype": "float32",
            "shape": [4],
            "names": ["start_x", "start_y", "end_x", "end_y"],
        },
        PAD_KEY: {"dtype": "bool", "shape": [1], "names": None},
    }
    stats: dict[str, Any] = {
        DEFAULT_ACTION: _stats(actions[~pad]),
        camera: {
            key: np.asarray(value).reshape(3, 1, 1).tolist() if key != "count" else value
            for key, value in _stats(
                pixels.numpy().reshape(-1, 3).astype(np.float64) / 255.0
            ).items()
        },
    }
    for key, values in states.items():
        name, width_ = STATE_KEYS[key], values.shape[-1]
        columns[name] = pa.FixedSizeListArray.from_arrays(pa.array(values.reshape(-1)), width_)
        names = (
            [f"{axis}_{i}" for i in range(width_ // 2) for axis in "xy"]
            if key == OBJECT_POS
            else [f"yaw_{i}" for i in range(width_)]
        )
        features[name] = {"dtype": "float32", "shape": [width_], "names": names}
        stats[name] = _stats(values.reshape(rows, width_))
    index_columns = {
        "timestamp": (frame_index / fps).astype(np.float32),
        "frame_index": frame_index,
        "episode_index": episode_index,
        "index": np.arange(rows, dtype=np.int64),
        "task_index": np.zeros(rows, dtype=np.int64),
    }
    for name, values in index_columns.items():
        columns[name] = pa.array(values)
        features[name] = {"dtype": str(values.dtype), "shape": [1], "names": None}
        stats[name] = _stats(values.astype(np.float64)[:, None])
    info = {
        "codebase_version": CODEBASE_VERSION,
        "robot_type": None,
        "total_episodes": num_episodes,
        "total_frames": rows,
        "total_tasks": 1,
        "chunks_size": 1000,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 500,
        "fps": fps,
        "splits": {"train": f"0:{num_episodes}"},
        "data_path": DATA_PATH,
        "video_path": None,
        "features": features,
        EXTRA_KEY: {
            "workspace_half_size": half,
            "action_units": "metres",
            "pad_key": PAD_KEY,
            "source": str(source.resolve()),
            "splits": metadata.get("splits"),
        },
    }
    starts = np.arange(num_episodes, dtype=np.int64) * frames
    zeros = np.zeros(num_episodes, dtype=np.int64)
    episode_table = pa.table(
        {
            "episode_index": pa.array(np.arange(num_episodes, dtype=np.int64)),
            "tasks": pa.array([[TASK]] * num_episodes, type=pa.list_(pa.string())),
            "length": pa.array(np.full(num_episodes, frames, dtype=np.int64)),
            "data/chunk_index": pa.array(zeros),
            "data/file_index": pa.array(zeros),
            "dataset_from_index": pa.array(starts),
            "dataset_to_index": pa.array(starts + frames),
            "meta/episodes/chunk_index": pa.array(zeros),
            "meta/episodes/file_index": pa.array(zeros),
        }
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        data_file = tmp / DATA_PATH.format(chunk_index=0, file_index=0)
        data_file.parent.mkdir(parents=True)
        pq.write_table(pa.table(columns), data_file)
        (tmp / EPISODES_PATH).parent.mkdir(parents=True)
        pq.write_table(episode_table, tmp / EPISODES_PATH)
        tasks = pa.table({"task_index": pa.array([0], type=pa.int64()), "task": [TASK]})
        pq.write_table(tasks, tmp / "meta" / "tasks.parquet")
        (tmp / "meta" / "stats.json").write_text(json.dumps(stats, indent=2))
        (tmp / INFO_FILE).write_text(json.dumps(info, indent=2))
        if out.exists():
            out.rmdir()  # empty, checked above
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


@dataclass(frozen=True)
class LeRobotEpisode:
    """One episode read back: ``frames`` uint8 ``[N, H, W, 3]``, ``pushes`` ``[N - 1, 4]``
    metres (table frame), and the dataset's ``workspace_half_size`` (metres)."""

    index: int
    frames: np.ndarray
    pushes: np.ndarray
    workspace_half_size: float


@dataclass(frozen=True)
class _ImportedEpisode(FolderEpisode):
    """A LeRobot episode as the importer sees a push folder's: ``frames`` are names only
    (``<folder>/episode_<i>/frame_<t>.png``); the pixels come from ``images`` (PNG bytes)."""

    images: tuple[bytes, ...] = ()

    def load_frames(self, start: int, stop: int) -> list[Image.Image]:
        out = []
        for data in self.images[start:stop]:
            with Image.open(io.BytesIO(data)) as image:
                if image.size != self.image_size:
                    raise FrameSizeError(
                        f"{self.path}: a frame is {image.size[0]}x{image.size[1]} px, the "
                        f"first {self.image_size[0]}x{self.image_size[1]} px."
                    )
                out.append(image.convert("RGB"))
        return out


class LeRobotSource:
    """A checked LeRobot v3.0 dataset (see :func:`read_lerobot`); iterate for its episodes."""

    def __init__(
        self,
        root: Path,
        camera_key: str,
        workspace_half_size: float,
        images: list[bytes],
        actions: np.ndarray,
        bounds: list[tuple[int, int, int]],
        image_size: tuple[int, int],
    ) -> None:
        self.root, self.camera_key = root, camera_key
        self.workspace_half_size = workspace_half_size
        self._images, self._actions, self._bounds = images, actions, bounds
        self.image_size = image_size  # (width, height)

    def __len__(self) -> int:
        return len(self._bounds)

    def _episode_images(self, start: int, stop: int) -> list[bytes]:
        return self._images[start:stop]

    def __iter__(self) -> Iterator[LeRobotEpisode]:
        for index, start, stop in self._bounds:
            frames = [
                np.asarray(Image.open(io.BytesIO(b)).convert("RGB"))
                for b in self._episode_images(start, stop)
            ]
            yield LeRobotEpisode(
                index,
                np.stack(frames),
                self._actions[start : stop - 1].astype(np.float64),
                self.workspace_half_size,
            )

    def as_push_folder(self) -> PushFolder:
        """The episodes as a checked :class:`PushFolder` (pushes normalised), for
        :func:`kinet_rl.data.importing.plan_import`; frames are decoded when imported."""
        half = self.workspace_half_size
        meta = FolderMeta(half, "metres", self.image_size, self.camera_key)
        episodes = []
        for index, start, stop in self._bounds:
            folder = self.root / f"episode_{index:06d}"
            pushes = self._actions[start : stop - 1].astype(np.float64) / half
            episodes.append(
                _ImportedEpisode(
                    folder,
                    tuple(folder / frame_name(t) for t in range(stop - start)),
                    pushes.astype(np.float32),
                    self.image_size,
                    tuple(self._images[start:stop]),
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
) -> LeRobotSource:
    """Reads and checks a LeRobot v3.0 dataset of images and 4-d pushes (metres).

    Every check runs here, before any frame is decoded. Episodes are ordered by
    ``episode_index``, their frames by ``frame_index``; the last action of each is dropped.

    Args:
        folder: The dataset folder (``meta/info.json``, ``data/``).
        camera_key: The image feature (dtype ``image``; videos are not supported yet).
        action_key: The action feature: 4 numbers, start and end point in metres.
        workspace_half_size: Metres; needed when ``info.json`` has no
            ``kinet_rl.workspace_half_size``.

    Raises:
        NotLeRobotDatasetError, LeRobotVersionError, MissingFeatureError, MissingWorkspaceError,
        ActionWidthError, NonFiniteActionError, OutsideWorkspaceError, ShortEpisodeError,
        FrameCountError: What is wrong, by name.
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
    if features[camera_key].get("dtype") != "image":
        raise MissingFeatureError(
            f"{camera_key!r} is a {features[camera_key].get('dtype')!r} feature; only 'image' "
            "(PNG in the Parquet files) is supported, not video yet."
        )
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
    pa, pq = _pyarrow()
    files = sorted((root / "data").glob("chunk-*/file-*.parquet"))
    if not files:
        raise NotLeRobotDatasetError(f"{root / 'data'} holds no chunk-*/file-*.parquet files.")
    wanted = [camera_key, action_key, "episode_index", "frame_index"]
    table = pa.concat_tables([pq.read_table(f, columns=wanted) for f in files])
    action_column = table.column(action_key).combine_chunks()
    lengths = np.asarray(pa.compute.list_value_length(action_column))
    if len(lengths) and (lengths != 4).any():
        raise ActionWidthError(
            f"{action_key!r} holds rows of {sorted(set(lengths.tolist()))} numbers; a push is 4."
        )
    actions = np.asarray(action_column.flatten(), dtype=np.float64).reshape(-1, 4)
    episode_index = np.asarray(table.column("episode_index"), dtype=np.int64)
    frame_index = np.asarray(table.column("frame_index"), dtype=np.int64)
    order = np.lexsort((frame_index, episode_index))
    actions, episode_index = actions[order], episode_index[order]
    cells = table.column(camera_key).to_pylist()
    images: list[bytes] = []
    for row in order.tolist():
        cell = cells[row]
        data = cell.get("bytes") if isinstance(cell, dict) else None
        if data is None and isinstance(cell, dict) and cell.get("path"):
            data = (root / cell["path"]).read_bytes()
        if data is None:
            raise NotLeRobotDatasetError(f"Frame {row} of {camera_key!r} holds no image bytes.")
        images.append(data)
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
                "check --workspace-half-size and the action's units (metres)."
            )
        bounds.append((int(index), start, stop))
    cam_shape = features[camera_key].get("shape") or []
    with Image.open(io.BytesIO(images[0])) as first:
        size = first.size
    if len(cam_shape) == 3 and tuple(cam_shape[:2]) != (size[1], size[0]):
        raise NotLeRobotDatasetError(
            f"{camera_key!r}: info.json states shape {cam_shape}, the first frame is "
            f"{size[0]}x{size[1]} px."
        )
    return LeRobotSource(root, camera_key, half, images, actions, bounds, size)
