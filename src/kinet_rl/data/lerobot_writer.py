"""LeRobot v3.0 writer: :func:`export_lerobot` writes a kinet_rl dataset in the layout that
:mod:`kinet_rl.data.lerobot` describes (and reads back).

As LeRobot's writer does, whole episodes fill a data file until the next would take it to
``data_files_size_in_mb`` (at the file's bytes per frame so far), a video file until the next
episode's video would take it to ``video_files_size_in_mb``; then the next file (``file_index``
+ 1; the next chunk after ``chunks_size`` files). Videos are written through
:mod:`kinet_rl.data.lerobot_video`.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from kinet_rl.data.lerobot import (
    CHUNKS_SIZE,
    CODEBASE_VERSION,
    DATA_FILES_SIZE_IN_MB,
    DATA_PATH,
    DEFAULT_ACTION,
    DEFAULT_CAMERA,
    DEFAULT_FPS,
    EPISODES_PATH,
    EXTRA_KEY,
    INFO_FILE,
    PAD_KEY,
    STATE_KEYS,
    TASK,
    VIDEO_FILES_SIZE_IN_MB,
    MissingWorkspaceError,
    TargetNotEmptyError,
    require_pyarrow,
)
from kinet_rl.data.lerobot_video import (
    MEGABYTE,
    VIDEO_PATH,
    next_file,
    require_av,
    video_info,
    write_videos,
)
from kinet_rl.data.storage import METADATA_FILE, open_episodes, read_json
from kinet_rl.keys import ACTION, OBJECT_POS, PIXELS


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
    video: bool = False,
    data_files_size_in_mb: float = DATA_FILES_SIZE_IN_MB,
    video_files_size_in_mb: float = VIDEO_FILES_SIZE_IN_MB,
) -> Path:
    """Writes the complete kinet_rl dataset ``dataset_path`` (all splits, in stored order) as a
    LeRobot v3.0 dataset at ``out_dir`` (see the module docstring), atomically: into a temporary
    folder beside it, renamed at the end.

    Args:
        dataset_path: A complete dataset folder (``metadata.json``).
        out_dir: The new folder; must not exist or be empty.
        camera: The camera feature's key.
        include_object_state: Also write the object positions and yaws, where stored.
        fps: Frames per second stated in ``info.json`` (kinet_rl's pushes have no clock).
        video: Store the camera as AV1 MP4 videos (lossy, small) instead of PNG images in the
            Parquet files (bit-exact).
        data_files_size_in_mb: A data Parquet file takes episodes until it would reach this.
        video_files_size_in_mb: A video file takes episodes until it would reach this.

    Returns:
        ``out_dir``.

    Raises:
        TargetNotEmptyError: ``out_dir`` exists and is not empty (nothing written).
        DatasetError: The dataset is missing, partial or corrupt.
        ImportError: pyarrow, or with ``video`` PyAV, is not installed.
    """
    pa, pq = require_pyarrow()
    source, out = Path(dataset_path), Path(out_dir)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise TargetNotEmptyError(f"{out} exists and is not empty; choose a new folder.")
    if video:
        require_av()  # before any work
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
        STATE_KEYS[key]: episodes[key].numpy().reshape(num_episodes, frames, -1).astype(np.float32)
        for key in STATE_KEYS
        if include_object_state and key in episodes.keys()  # noqa: SIM118 (a TensorDict)
    }
    rows = num_episodes * frames
    pad = np.zeros((num_episodes, frames), dtype=bool)
    pad[:, -1] = True
    actions = np.zeros((num_episodes, frames, 4), dtype=np.float32)
    actions[:, :-1] = action
    frame_index = np.arange(frames, dtype=np.int64)
    index_columns = {  # [E, T + 1] each
        "timestamp": np.tile((frame_index / fps).astype(np.float32), (num_episodes, 1)),
        "frame_index": np.tile(frame_index, (num_episodes, 1)),
        "episode_index": np.repeat(np.arange(num_episodes, dtype=np.int64)[:, None], frames, 1),
        "index": np.arange(rows, dtype=np.int64).reshape(num_episodes, frames),
        "task_index": np.zeros((num_episodes, frames), dtype=np.int64),
    }
    features: dict[str, Any] = {
        camera: {
            "dtype": "video" if video else "image",
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
    for name, values in states.items():
        width_ = values.shape[-1]
        names = (
            [f"{axis}_{i}" for i in range(width_ // 2) for axis in "xy"]
            if name == STATE_KEYS[OBJECT_POS]
            else [f"yaw_{i}" for i in range(width_)]
        )
        features[name] = {"dtype": "float32", "shape": [width_], "names": names}
        stats[name] = _stats(values.reshape(rows, width_))
    for name, values in index_columns.items():
        features[name] = {"dtype": str(values.dtype), "shape": [1], "names": None}
        stats[name] = _stats(values.reshape(-1, 1).astype(np.float64))

    def episode_table(e: int) -> Any:
        columns: dict[str, Any] = {}
        if not video:
            columns[camera] = pa.array(
                [{"bytes": _png(frame), "path": None} for frame in pixels[e].numpy()],
                type=pa.struct([("bytes", pa.binary()), ("path", pa.string())]),
            )
        columns[DEFAULT_ACTION] = pa.FixedSizeListArray.from_arrays(
            pa.array(actions[e].reshape(-1)), 4
        )
        columns[PAD_KEY] = pa.array(pad[e])
        for name, values in states.items():
            columns[name] = pa.FixedSizeListArray.from_arrays(
                pa.array(values[e].reshape(-1)), values.shape[-1]
            )
        columns.update({name: pa.array(values[e]) for name, values in index_columns.items()})
        return pa.table(columns)

    info = {
        "codebase_version": CODEBASE_VERSION,
        "robot_type": None,
        "total_episodes": num_episodes,
        "total_frames": rows,
        "total_tasks": 1,
        "chunks_size": CHUNKS_SIZE,
        "data_files_size_in_mb": data_files_size_in_mb,
        "video_files_size_in_mb": video_files_size_in_mb,
        "fps": fps,
        "splits": {"train": f"0:{num_episodes}"},
        "data_path": DATA_PATH,
        "video_path": VIDEO_PATH if video else None,
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
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        files = _write_data(
            tmp, (episode_table(e) for e in range(num_episodes)), data_files_size_in_mb
        )
        table: dict[str, Any] = {
            "episode_index": np.arange(num_episodes, dtype=np.int64),
            "tasks": pa.array([[TASK]] * num_episodes, type=pa.list_(pa.string())),
            "length": np.full(num_episodes, frames, dtype=np.int64),
            "data/chunk_index": np.array([chunk for chunk, _ in files], dtype=np.int64),
            "data/file_index": np.array([file for _, file in files], dtype=np.int64),
            "dataset_from_index": starts,
            "dataset_to_index": starts + frames,
            "meta/episodes/chunk_index": zeros,
            "meta/episodes/file_index": zeros,
        }
        if video:
            placed = write_videos(
                (pixels[e].numpy() for e in range(num_episodes)),
                tmp,
                camera,
                fps,
                video_files_size_in_mb,
                CHUNKS_SIZE,
            )
            prefix = f"videos/{camera}/"
            table[prefix + "chunk_index"] = np.array([v.chunk_index for v in placed], np.int64)
            table[prefix + "file_index"] = np.array([v.file_index for v in placed], np.int64)
            table[prefix + "from_timestamp"] = np.array([v.from_timestamp for v in placed])
            table[prefix + "to_timestamp"] = np.array([v.to_timestamp for v in placed])
            first = tmp / VIDEO_PATH.format(video_key=camera, chunk_index=0, file_index=0)
            features[camera]["info"] = video_info(first)
        (tmp / EPISODES_PATH).parent.mkdir(parents=True)
        pq.write_table(pa.table(table), tmp / EPISODES_PATH)
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


def _write_data(root: Path, tables: Iterable[Any], file_size_in_mb: float) -> list[tuple[int, int]]:
    """Writes each episode's table at :data:`DATA_PATH` under ``root``, whole episodes per file,
    a new file when the current one plus the episode (at the file's bytes per frame so far)
    would reach ``file_size_in_mb`` (LeRobot's ``_save_episode_data``); returns each episode's
    ``(chunk_index, file_index)``."""
    _, pq = require_pyarrow()
    placed: list[tuple[int, int]] = []
    writer, path, chunk_index, file_index, frames_in_file = None, root, 0, 0, 0
    try:
        for table in tables:
            if writer is not None:
                size_mb = path.stat().st_size / MEGABYTE
                if size_mb + size_mb / frames_in_file * table.num_rows >= file_size_in_mb:
                    writer.close()
                    writer = None
                    chunk_index, file_index = next_file(chunk_index, file_index, CHUNKS_SIZE)
            if writer is None:
                path = root / DATA_PATH.format(chunk_index=chunk_index, file_index=file_index)
                path.parent.mkdir(parents=True, exist_ok=True)
                writer, frames_in_file = pq.ParquetWriter(path, table.schema), 0
            writer.write_table(table)
            frames_in_file += table.num_rows
            placed.append((chunk_index, file_index))
    finally:
        if writer is not None:
            writer.close()
    return placed
