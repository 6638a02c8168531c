"""LeRobot v3.0 video storage through PyAV: a camera's frames as AV1 MP4 files, episodes back to
back.

The layout is LeRobot's (``lerobot/datasets/dataset_writer.py``, ``video_utils.py`` and
``v30/convert_dataset_v21_to_v30.py``, LeRobot 0.4 to 0.6): every episode is encoded on its own
(libsvtav1, yuv420p, ``g`` 2, ``crf`` 30, preset 12, LeRobot's defaults) and appended to its
camera's current file by stream copy (FFmpeg's concat demuxer); a new file starts when the
current one plus the episode would reach ``video_files_size_in_mb``. The episode table records
``videos/<key>/chunk_index``, ``file_index``, ``from_timestamp`` and ``to_timestamp`` (seconds
in that file, each episode's starting where the one before it in the file ends); LeRobot reads
frame ``t`` of an episode at ``from_timestamp + timestamp``.

Reading: :func:`check_videos` assigns every packet of every file (demuxed, not decoded) to an
episode's frame by its time, so a missing video file, a missing or an extra frame is a named
error before anything is decoded; :class:`VideoFrames` then decodes an episode when asked,
sequentially from where the one before it in the same file ended, and keeps one episode's frames
in memory. A frame belongs to the episode frame whose expected time is nearest, within half a
frame (``1 / (2 fps)``).

The base :class:`LeRobotError` lives here, below :mod:`kinet_rl.data.lerobot`, which imports it.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from kinet_rl.data.push_folder import FrameSizeError, PushFolderError

INSTALL_HINT = "pip install 'kinet_rl[lerobot]' (pyarrow, av)"
VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
CODEC, PIX_FMT = "libsvtav1", "yuv420p"
#: LeRobot's default libsvtav1 options (``VideoEncoderConfig``, ``_get_codec_options``).
CODEC_OPTIONS = {"g": "2", "crf": "30", "preset": "12"}
MEGABYTE = 1024**2


class LeRobotError(PushFolderError):
    """A LeRobot dataset cannot be read or written; the message names the fix."""


class MissingVideoError(LeRobotError):
    """A video file the episode table points at is absent, or an episode has no video entry."""


class VideoFrameError(LeRobotError):
    """A video file holds a frame too few or too many for the episodes it stores."""


def require_av() -> Any:
    """The ``av`` module (PyAV).

    Raises:
        ImportError: PyAV is not installed; the message says how to install it.
    """
    try:
        import av
    except ImportError as err:  # pragma: no cover - the extra is installed in CI
        raise ImportError(f"LeRobot video features need PyAV: {INSTALL_HINT}") from err
    return av


def next_file(chunk_index: int, file_index: int, chunks_size: int) -> tuple[int, int]:
    """The file after ``(chunk_index, file_index)`` (LeRobot's ``update_chunk_file_indices``)."""
    if file_index == chunks_size - 1:
        return chunk_index + 1, 0
    return chunk_index, file_index + 1


def encode_episode(frames: np.ndarray, path: Path, fps: int) -> None:
    """Writes ``frames`` (uint8 ``[N, H, W, 3]``) as an AV1 MP4 of ``fps`` frames per second."""
    av = require_av()
    os.environ.setdefault("SVT_LOG", "1")  # SVT-AV1: errors only, not its info banner
    with av.open(str(path), "w") as container:
        stream = container.add_stream(CODEC, rate=fps, options=CODEC_OPTIONS)
        stream.pix_fmt = PIX_FMT
        stream.height, stream.width = int(frames.shape[1]), int(frames.shape[2])
        for frame in frames:
            image = av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24")
            container.mux(stream.encode(image))
        container.mux(stream.encode())  # flush


def duration_s(path: Path) -> float:
    """Seconds of the video stream of ``path`` (LeRobot's ``get_video_duration_in_s``)."""
    av = require_av()
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        if stream.duration is not None:
            return float(stream.duration * stream.time_base)
        return float(container.duration / av.time_base)


def concatenate(paths: Sequence[Path], out: Path) -> None:
    """Writes the videos ``paths`` one after the other into ``out`` by stream copy (FFmpeg's
    concat demuxer, as LeRobot's ``concatenate_video_files``): no re-encoding."""
    av = require_av()
    with tempfile.NamedTemporaryFile("w", suffix=".ffconcat", dir=out.parent, delete=False) as f:
        f.write("ffconcat version 1.0\n")
        for path in paths:
            quoted = str(path.resolve()).replace("'", "'\\''")
            f.write(f"file '{quoted}'\n")
    try:
        with (
            av.open(f.name, "r", format="concat", options={"safe": "0"}) as source,
            av.open(str(out), "w", options={"movflags": "faststart"}) as target,
        ):
            streams = {}
            for stream in source.streams.video:
                streams[stream.index] = target.add_stream_from_template(stream, opaque=True)
                streams[stream.index].time_base = stream.time_base
            for packet in source.demux():
                if packet.stream.index not in streams or packet.dts is None:
                    continue  # flushing packets and other streams
                packet.stream = streams[packet.stream.index]
                target.mux(packet)
    finally:
        os.unlink(f.name)


@dataclass(frozen=True)
class EpisodeVideo:
    """Where an episode's frames lie: video file ``(chunk_index, file_index)`` of its camera,
    seconds ``[from_timestamp, to_timestamp)`` of that file."""

    chunk_index: int
    file_index: int
    from_timestamp: float
    to_timestamp: float


def write_videos(
    episodes: Iterable[np.ndarray],
    root: Path,
    key: str,
    fps: int,
    file_size_in_mb: float,
    chunks_size: int,
) -> list[EpisodeVideo]:
    """Encodes each episode's frames (uint8 ``[N, H, W, 3]``) and stores them under ``root`` at
    :data:`VIDEO_PATH`, back to back, a new file when the current one plus the episode would
    reach ``file_size_in_mb`` (the v3.0 conversion's rule); returns where each episode lies."""
    scratch = Path(tempfile.mkdtemp(prefix=".episodes.", dir=root))
    placed: list[EpisodeVideo] = []
    group: list[Path] = []
    chunk_index = file_index = 0
    size_mb = seconds = 0.0

    def store() -> None:
        target = root / VIDEO_PATH.format(
            video_key=key, chunk_index=chunk_index, file_index=file_index
        )
        target.parent.mkdir(parents=True, exist_ok=True)
        if len(group) == 1:
            os.replace(group[0], target)
        else:
            concatenate(group, target)

    try:
        for index, frames in enumerate(episodes):
            path = scratch / f"episode_{index:06d}.mp4"
            encode_episode(frames, path, fps)
            episode_mb, episode_s = path.stat().st_size / MEGABYTE, duration_s(path)
            if group and size_mb + episode_mb >= file_size_in_mb:
                store()
                chunk_index, file_index = next_file(chunk_index, file_index, chunks_size)
                group, size_mb, seconds = [], 0.0, 0.0
            placed.append(EpisodeVideo(chunk_index, file_index, seconds, seconds + episode_s))
            group.append(path)
            size_mb, seconds = size_mb + episode_mb, seconds + episode_s
        if group:
            store()
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return placed


def video_info(path: Path) -> dict[str, Any]:
    """A video feature's ``info`` entry, read from the file's header (LeRobot 0.4's
    ``get_video_info``)."""
    av = require_av()
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        return {
            "video.height": stream.height,
            "video.width": stream.width,
            "video.codec": stream.codec.canonical_name,
            "video.pix_fmt": stream.pix_fmt,
            "video.is_depth_map": False,
            "video.fps": int(stream.base_rate),
            "video.channels": 3,
            "has_audio": bool(container.streams.audio),
        }


@dataclass(frozen=True)
class EpisodeClip:
    """An episode's frames in a video file: ``times`` (seconds in ``path``) of frames 0, 1, ...

    ``index`` is the episode's ``episode_index``.
    """

    index: int
    path: Path
    times: np.ndarray


def _assign(path: Path, times: np.ndarray, clips: Sequence[EpisodeClip], tolerance: float) -> Any:
    """``(clip, frame)`` of each frame time (seconds), the nearest expected time within
    ``tolerance``; every expected frame exactly once.

    Raises:
        VideoFrameError: A frame near no expected time, two near one, or one expected frame
            without a frame.
    """
    expected = np.concatenate([clip.times for clip in clips])
    owner = np.concatenate([np.full(len(clip.times), i) for i, clip in enumerate(clips)])
    frame = np.concatenate([np.arange(len(clip.times)) for clip in clips])
    order = np.argsort(expected, kind="stable")
    expected, owner, frame = expected[order], owner[order], frame[order]
    right = np.clip(np.searchsorted(expected, times), 0, len(expected) - 1)
    left = np.clip(right - 1, 0, len(expected) - 1)
    nearest = np.where(
        np.abs(expected[left] - times) <= np.abs(expected[right] - times), left, right
    )
    counts = f"{path} holds {len(times)} frame(s) there; its episodes expect {len(expected)}"
    far = np.abs(expected[nearest] - times) > tolerance
    if far.any():
        raise VideoFrameError(
            f"{path}: a frame at {times[far][0]:.4f} s belongs to no episode's frame ({counts}; "
            "the episode table's from_timestamp / to_timestamp do not match the file)."
        )
    hits = np.bincount(nearest, minlength=len(expected))
    for problem, mask in (("2 or more frames", hits > 1), ("no frame", hits == 0)):
        if mask.any():
            i = int(np.flatnonzero(mask)[0])
            clip = clips[owner[i]]
            raise VideoFrameError(
                f"{path}: {problem} for frame {frame[i]} of episode {clip.index} (expected at "
                f"{expected[i]:.4f} s; {counts}). Re-encode the episode or drop it."
            )
    return owner[nearest], frame[nearest]


def episode_clips(
    root: Path, video_path: str, key: str, episodes: Sequence[tuple[int, np.ndarray]]
) -> list[EpisodeClip]:
    """Where each episode's frames lie in camera ``key``'s videos, from the episode table
    (``meta/episodes/``): ``episodes`` are ``(episode_index, timestamps of its frames)``, the
    data's ``timestamp`` column; frame ``t`` is at ``from_timestamp + timestamp[t]``.

    Raises:
        MissingVideoError: The episode table lacks the ``videos/<key>/...`` columns or an
            episode's row.
        VideoFrameError: An episode's frames end after its ``to_timestamp``.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    folder = root / "meta" / "episodes"
    columns = ("chunk_index", "file_index", "from_timestamp", "to_timestamp")
    names = ["episode_index", *(f"videos/{key}/{name}" for name in columns)]
    tables = []
    for file in sorted(folder.glob("chunk-*/file-*.parquet")):
        missing = sorted(set(names) - set(pq.read_schema(file).names))
        if missing:
            raise MissingVideoError(
                f"{file} has no column(s) {missing}: the episode table does not say where "
                f"{key!r}'s frames lie in its videos."
            )
        tables.append(pq.read_table(file, columns=names))
    if not tables:
        raise MissingVideoError(f"{folder} holds no chunk-*/file-*.parquet (the episode table).")
    table = pa.concat_tables(tables)
    values = [table.column(name).to_pylist() for name in names]
    rows = {row[0]: row[1:] for row in zip(*values, strict=True)}
    clips = []
    for index, timestamps in episodes:
        if index not in rows:
            raise MissingVideoError(
                f"Episode {index} has no row in {folder}: where its frames lie in {key!r}'s "
                "videos is unknown."
            )
        chunk_index, file_index, begin, end = rows[index]
        path = root / video_path.format(
            video_key=key, chunk_index=chunk_index, file_index=file_index
        )
        times = begin + np.asarray(timestamps, dtype=np.float64)
        if times[-1] >= end:
            raise VideoFrameError(
                f"Episode {index}: its {len(times)} frames run to {times[-1]:.4f} s of {path}, "
                f"past its to_timestamp {end:.4f} s in {folder}."
            )
        clips.append(EpisodeClip(index, path, times))
    return clips


def check_videos(clips: Sequence[EpisodeClip], fps: float) -> tuple[int, int]:
    """Checks the video files of ``clips`` without decoding them: every file exists, and its
    packets' times give each clip's frames exactly once (each file holding only frames of its
    clips). Returns the frames' ``(width, height)``.

    Raises:
        MissingVideoError: A file is absent (all checked before any is read).
        VideoFrameError: A frame too few or too many (see :func:`_assign`), or a file that
            is not a readable video.
        FrameSizeError: The files' frames differ in size.
    """
    av = require_av()
    missing = sorted({str(clip.path) for clip in clips if not clip.path.is_file()})
    if missing:
        raise MissingVideoError(
            f"{len(missing)} video file(s) of the episode table are absent, e.g. {missing[0]}; "
            "download the dataset's videos/ folder too."
        )
    by_file: dict[Path, list[EpisodeClip]] = {}
    for clip in clips:
        by_file.setdefault(clip.path, []).append(clip)
    sizes = {}
    for path, file_clips in by_file.items():
        try:
            with av.open(str(path)) as container:
                if not container.streams.video:
                    raise VideoFrameError(f"{path} holds no video stream.")
                stream = container.streams.video[0]
                sizes[path] = (stream.codec_context.width, stream.codec_context.height)
                times = [
                    float(packet.pts * stream.time_base)
                    for packet in container.demux(stream)
                    if packet.pts is not None and packet.size
                ]
        except av.FFmpegError as err:
            raise VideoFrameError(f"{path} is not a readable video ({err}).") from err
        _assign(path, np.asarray(times), file_clips, 0.5 / fps)
    if len(set(sizes.values())) > 1:
        raise FrameSizeError(f"The video files' frames differ in size: {sizes}.")
    return next(iter(sizes.values()))


class _Cursor:
    """Decodes one video file forward from a time; one frame may be put back."""

    def __init__(self, path: Path, start: float) -> None:
        self.path = path
        self._container = require_av().open(str(path))
        stream = self._container.streams.video[0]
        if start > 0:  # to the keyframe at or before ``start`` (as LeRobot's PyAV decoder)
            offset = max(0, round(start / stream.time_base) - 1)
            self._container.seek(offset, backward=True, any_frame=False, stream=stream)
        self._frames = self._container.decode(stream)
        self._back: tuple[float, Any] | None = None
        #: The time of the last frame taken (and not put back).
        self.taken = self._before = -math.inf

    def take(self) -> tuple[float, Any] | None:
        """The next frame ``(seconds, av.VideoFrame)``, or None at the end (file closed)."""
        if self._back is not None:
            item, self._back = self._back, None
        else:
            frame = next((f for f in self._frames if f.time is not None), None)
            if frame is None:
                self.close()
                return None
            item = (float(frame.time), frame)
        self._before, self.taken = self.taken, item[0]
        return item

    def put_back(self, item: tuple[float, Any]) -> None:
        """Undoes the last :meth:`take`."""
        self._back, self.taken = item, self._before

    def close(self) -> None:
        self._frames = iter(())
        self._container.close()


class VideoFrames:
    """The frames of checked clips (:func:`check_videos`), decoded an episode at a time."""

    def __init__(self, clips: Sequence[EpisodeClip], fps: float) -> None:
        self._clips, self._tolerance = tuple(clips), 0.5 / fps
        self._cursor: _Cursor | None = None
        self._cached: tuple[int, list[np.ndarray]] | None = None

    def frames(self, position: int, start: int, stop: int) -> list[Image.Image]:
        """Frames ``start:stop`` of the clip at ``position``, as RGB images.

        Raises:
            VideoFrameError: The decoded frames are not the clip's, once each, or the file
                cannot be decoded.
        """
        if self._cached is None or self._cached[0] != position:
            clip = self._clips[position]
            try:
                self._cached = (position, self._decode(clip))
            except require_av().FFmpegError as err:
                self._cursor = None
                raise VideoFrameError(f"{clip.path} cannot be decoded ({err}).") from err
        return [Image.fromarray(frame) for frame in self._cached[1][start:stop]]

    def _decode(self, clip: EpisodeClip) -> list[np.ndarray]:
        first, last = clip.times[0] - self._tolerance, clip.times[-1] + self._tolerance
        cursor = self._cursor
        if cursor is None or cursor.path != clip.path or cursor.taken >= first:
            if cursor is not None:
                cursor.close()
            cursor = self._cursor = _Cursor(clip.path, float(clip.times[0]))
        times, images = [], []
        while (item := cursor.take()) is not None:
            if item[0] < first:
                continue  # the episode before, or the keyframe a seek landed on
            if item[0] > last:
                cursor.put_back(item)
                break
            times.append(item[0])
            images.append(item[1].to_ndarray(format="rgb24"))
        _, frame = _assign(clip.path, np.asarray(times), [clip], self._tolerance)
        return [images[i] for i in np.argsort(frame)]
