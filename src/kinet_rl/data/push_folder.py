"""A robot's pushes as a plain folder of PNG frames and one pushes file per episode.

The format (docs/data.md, "Your own robot's pushes")::

    <root>/
      meta.json                {"format": "kinet_rl.push_folder", "version": 1,
                                "workspace_half_size": 0.25, "units": "metres",
                                "image_size": [640, 480], "camera": "realsense_top"}
      episode_000000/
        frame_000000.png       the frame before push 0
        frame_000001.png       after push 0, before push 1
        ...
        frame_<N-1>.png        the last frame: no push after it
        pushes.csv             N - 1 rows "start_x,start_y,end_x,end_y" after that header
      episode_000001/ ...

``workspace_half_size`` (metres) is half the side of the square workspace centred on the table
origin; pushes are start and end points in the table frame, in metres (``units: metres``) or
already divided by the half size (``units: normalised``, in ``[-1, 1]``). ``image_size``
(width, height) and ``camera`` are optional; with ``image_size`` every frame must have it.
Instead of ``pushes.csv`` an episode may hold ``pushes.json`` (a list of ``[start_x, start_y,
end_x, end_y]``) or ``pushes.npz`` (an array ``pushes`` ``[N - 1, 4]``), exactly one of them.
Names starting with a dot are ignored (the open episode of a
:class:`~kinet_rl.data.recorder.PushRecorder`).

:func:`read_push_folder` checks a whole folder before anything is converted and raises a named
:class:`PushFolderError` for what is wrong; :class:`~kinet_rl.data.recorder.PushRecorder` writes
the format from a robot's loop, one step at a time, and survives a crash.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, UnidentifiedImageError

from kinet_rl.data.storage import DatasetError

META_FILE = "meta.json"
FOLDER_FORMAT = "kinet_rl.push_folder"
FOLDER_VERSION = 1
EPISODE_PATTERN = re.compile(r"episode_(\d+)")
FRAME_PATTERN = re.compile(r"frame_(\d+)\.png")
PUSH_COLUMNS = ("start_x", "start_y", "end_x", "end_y")
PUSHES_CSV, PUSHES_JSON, PUSHES_NPZ = "pushes.csv", "pushes.json", "pushes.npz"
PUSH_FILES = (PUSHES_CSV, PUSHES_JSON, PUSHES_NPZ)
UNITS = ("metres", "normalised")
#: Folder of the episode a ``PushRecorder`` is recording (ignored by readers).
RECORDING_DIR = ".recording"
#: Pushes may overshoot the workspace by this much (normalised units) for rounding.
WORKSPACE_TOLERANCE = 1e-6


def episode_name(index: int) -> str:
    """The folder name of episode ``index``."""
    return f"episode_{index:06d}"


def frame_name(index: int) -> str:
    """The file name of frame ``index`` of an episode."""
    return f"frame_{index:06d}.png"


class PushFolderError(DatasetError):
    """A plain push folder cannot be imported; the message names the file and the fix."""


class NotPushFolderError(PushFolderError):
    """The folder is not in the format: no or a bad ``meta.json``, no episodes, misnamed or
    unreadable frames, no pushes file or several."""


class ActionWidthError(PushFolderError):
    """A pushes file holds rows of other than 4 numbers (start x, y, end x, y)."""


class NonFiniteActionError(PushFolderError):
    """A push holds NaN or an infinite number."""


class ShortEpisodeError(PushFolderError):
    """An episode holds fewer than 2 frames: no push with a frame after it."""


class FrameCountError(PushFolderError):
    """An episode's frame and push counts disagree: N frames need N - 1 pushes."""


class FrameSizeError(PushFolderError):
    """A frame's size differs from ``meta.json``'s ``image_size`` or from the other frames."""


class OutsideWorkspaceError(PushFolderError):
    """A push starts or ends outside the workspace stated in ``meta.json``."""


@dataclass(frozen=True)
class FolderMeta:
    """The contents of a push folder's ``meta.json``.

    Attributes:
        workspace_half_size: Half the side of the square workspace, metres.
        units: ``"metres"`` (table frame) or ``"normalised"`` (metres / ``workspace_half_size``).
        image_size: ``(width, height)`` of every frame in pixels, or None (not stated).
        camera: The camera's name (free text), or None.
    """

    workspace_half_size: float
    units: str = "metres"
    image_size: tuple[int, int] | None = None
    camera: str | None = None

    def __post_init__(self) -> None:
        half = self.workspace_half_size
        if isinstance(half, bool) or not isinstance(half, (int, float)) or not 0 < half < math.inf:
            raise ValueError(f"workspace_half_size must be metres > 0, got {half!r}.")
        if self.units not in UNITS:
            raise ValueError(f"units must be one of {list(UNITS)}, got {self.units!r}.")
        size = self.image_size
        if size is not None and (
            len(size) != 2 or not all(isinstance(v, int) and v > 0 for v in size)
        ):
            raise ValueError(f"image_size must be [width, height] in pixels, got {size!r}.")

    @classmethod
    def read(cls, root: Path) -> FolderMeta:
        """Reads and checks ``<root>/meta.json``.

        Raises:
            NotPushFolderError: It is missing, unreadable or holds other entries or values.
        """
        path = root / META_FILE
        hint = (
            f'Write {path} as {{"format": "{FOLDER_FORMAT}", "version": {FOLDER_VERSION}, '
            '"workspace_half_size": <metres>, "units": "metres"} (docs/data.md).'
        )
        if not root.is_dir():
            raise NotPushFolderError(f"{root} is not a folder. {hint}")
        if not path.is_file():
            raise NotPushFolderError(f"{root} is not a push folder: it has no {META_FILE}. {hint}")
        try:
            record = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise NotPushFolderError(f"Cannot read {path} ({err}). {hint}") from err
        if not isinstance(record, dict) or record.get("format") != FOLDER_FORMAT:
            raise NotPushFolderError(f"{path} does not say format {FOLDER_FORMAT!r}. {hint}")
        if record.get("version") != FOLDER_VERSION:
            raise NotPushFolderError(
                f"{path} has version {record.get('version')!r}; this kinet_rl reads version "
                f"{FOLDER_VERSION}. {hint}"
            )
        known = {"format", "version", "workspace_half_size", "units", "image_size", "camera"}
        unknown = sorted(set(record) - known)
        if unknown or "workspace_half_size" not in record:
            what = f"unknown entries {unknown}" if unknown else "no workspace_half_size"
            raise NotPushFolderError(f"{path} has {what}. {hint}")
        size = record.get("image_size")
        try:
            return cls(
                workspace_half_size=record["workspace_half_size"],
                units=record.get("units", "metres"),
                image_size=None if size is None else tuple(size),
                camera=record.get("camera"),
            )
        except (TypeError, ValueError) as err:
            raise NotPushFolderError(f"{path}: {err} {hint}") from err

    def as_json(self) -> dict[str, Any]:
        """The ``meta.json`` record."""
        record: dict[str, Any] = {
            "format": FOLDER_FORMAT,
            "version": FOLDER_VERSION,
            "workspace_half_size": self.workspace_half_size,
            "units": self.units,
        }
        if self.image_size is not None:
            record["image_size"] = list(self.image_size)
        if self.camera is not None:
            record["camera"] = self.camera
        return record

    def normalise(self, pushes: np.ndarray) -> np.ndarray:
        """Pushes ``[..., 4]`` in this folder's units -> normalised action units."""
        if self.units == "normalised":
            return pushes
        return pushes / self.workspace_half_size


@dataclass(frozen=True)
class FolderEpisode:
    """One checked episode of a push folder.

    Attributes:
        path: Its folder.
        frames: Its N frame files, in order.
        pushes: ``[N - 1, 4]`` float32 pushes in normalised action units (``[-1, 1]``).
        image_size: ``(width, height)`` of its frames.
    """

    path: Path
    frames: tuple[Path, ...]
    pushes: np.ndarray
    image_size: tuple[int, int]

    @property
    def name(self) -> str:
        return self.path.name

    def load_frames(self, start: int, stop: int) -> list[Image.Image]:
        """Frames ``start:stop`` as RGB images."""
        images = []
        for path in self.frames[start:stop]:
            with Image.open(path) as image:
                images.append(image.convert("RGB"))
        return images


@dataclass(frozen=True)
class PushFolder:
    """A checked push folder: its ``meta.json`` and its episodes in name order."""

    root: Path
    meta: FolderMeta
    episodes: tuple[FolderEpisode, ...]

    @property
    def image_size(self) -> tuple[int, int]:
        """``(width, height)`` of every frame."""
        return self.episodes[0].image_size

    def fingerprint(self) -> str:
        """SHA-256 over the episodes' names, frame counts and pushes: what an import converts
        (a resumed import of a folder that changed meanwhile is refused)."""
        digest = hashlib.sha256()
        for episode in self.episodes:
            digest.update(f"{episode.name}:{len(episode.frames)};".encode())
            digest.update(np.ascontiguousarray(episode.pushes).tobytes())
        return digest.hexdigest()


def read_pushes(path: Path) -> np.ndarray:
    """The pushes of a ``pushes.csv``, ``.json`` or ``.npz`` file as float64 ``[P, 4]``.

    Raises:
        NotPushFolderError: The file cannot be parsed.
        ActionWidthError: Its rows are not 4 numbers wide.
    """
    rows: Any
    try:
        if path.name == PUSHES_CSV:
            rows = _csv_rows(path)
        elif path.name == PUSHES_JSON:
            record = json.loads(path.read_text())
            rows = record.get("pushes") if isinstance(record, dict) else record
            if not isinstance(rows, list):
                raise ValueError("expected a list of pushes [start_x, start_y, end_x, end_y]")
        else:
            with np.load(path, allow_pickle=False) as archive:
                if "pushes" not in archive:
                    raise ValueError(f"no array 'pushes' (it has {sorted(archive.files)})")
                array = archive["pushes"]
            if array.ndim != 2:
                raise ActionWidthError(
                    f"{path}: the array 'pushes' has shape {array.shape}; it must be [P, 4] "
                    f"({', '.join(PUSH_COLUMNS)}), one row per push."
                )
            rows = array.tolist()
        widths = sorted({len(row) if isinstance(row, list) else 1 for row in rows})
        if any(width != 4 for width in widths):
            raise ActionWidthError(
                f"{path} holds pushes of {widths} numbers; each push is 4 numbers "
                f"({', '.join(PUSH_COLUMNS)}): start and end point in the table frame."
            )
        return np.asarray(rows, dtype=np.float64).reshape(-1, 4)
    except (OSError, ValueError, TypeError, UnicodeDecodeError) as err:
        raise NotPushFolderError(
            f"Cannot read the pushes in {path} ({err}). Write one push per row: "
            f"{', '.join(PUSH_COLUMNS)} (docs/data.md)."
        ) from err


def _csv_rows(path: Path) -> list[list[float]]:
    """The rows of a ``pushes.csv`` after its header, as floats (``nan`` and ``inf`` parse)."""
    with open(path, newline="") as f:
        lines = [row for row in csv.reader(f) if row]
    if not lines:
        raise ValueError(f"it is empty; its first line must be the header {','.join(PUSH_COLUMNS)}")
    header = [name.strip() for name in lines[0]]
    if len(header) != len(PUSH_COLUMNS):
        raise ActionWidthError(
            f"{path} has {len(header)} columns ({','.join(header)}); a push is 4 numbers: "
            f"{','.join(PUSH_COLUMNS)}."
        )
    if tuple(header) != PUSH_COLUMNS:
        raise ValueError(f"its header is {','.join(header)}, not {','.join(PUSH_COLUMNS)}")
    return [[float(value) for value in row] for row in lines[1:]]


def frame_files(folder: Path) -> tuple[Path, ...]:
    """The ``frame_<i>.png`` files of an episode folder, checked to number 0, 1, ..., N - 1."""
    frames = {}
    for path in folder.iterdir():
        match = FRAME_PATTERN.fullmatch(path.name)
        if match:
            frames[int(match.group(1))] = path
    if sorted(frames) != list(range(len(frames))):
        missing = sorted(set(range(max(frames, default=-1) + 1)) - set(frames))
        raise NotPushFolderError(
            f"{folder}: frames must be numbered frame_000000.png, frame_000001.png, ... without "
            f"gaps; missing {[frame_name(i) for i in missing[:5]]}."
        )
    return tuple(frames[i] for i in range(len(frames)))


def _image_size(path: Path) -> tuple[int, int]:
    """``(width, height)`` of an image file, read from its header."""
    try:
        with Image.open(path) as image:
            return image.size
    except (OSError, UnidentifiedImageError) as err:
        raise NotPushFolderError(f"Cannot read the image {path} ({err}).") from err


def read_episode(folder: Path, meta: FolderMeta) -> FolderEpisode:
    """Reads and checks one episode folder (see the module docstring).

    Raises:
        PushFolderError: The named error of what is wrong (see the subclasses).
    """
    frames = frame_files(folder)
    if len(frames) < 2:
        raise ShortEpisodeError(
            f"{folder} holds {len(frames)} frame(s); an episode needs at least 2 (a frame, the "
            "push that followed it, the frame after that push). Delete it or record more."
        )
    files = [folder / name for name in PUSH_FILES if (folder / name).is_file()]
    if len(files) != 1:
        found = [f.name for f in files] or "none"
        raise NotPushFolderError(
            f"{folder} must hold exactly one pushes file of {list(PUSH_FILES)}; found {found}."
        )
    pushes = read_pushes(files[0])
    if len(pushes) != len(frames) - 1:
        raise FrameCountError(
            f"{folder} holds {len(frames)} frames and {len(pushes)} pushes in {files[0].name}; "
            f"{len(frames)} frames need {len(frames) - 1} pushes (one between each two frames; "
            "the last frame has no push after it)."
        )
    bad = np.flatnonzero(~np.isfinite(pushes).all(axis=1))
    if bad.size:
        raise NonFiniteActionError(
            f"{files[0]}: push(es) {bad[:5].tolist()} hold NaN or infinite numbers "
            f"({pushes[bad[0]].tolist()}); fix or drop that episode."
        )
    normalised = meta.normalise(pushes)
    outside = np.flatnonzero((np.abs(normalised) > 1 + WORKSPACE_TOLERANCE).any(axis=1))
    if outside.size:
        limit = (
            "[-1, 1] (units: normalised)"
            if meta.units == "normalised"
            else f"+-{meta.workspace_half_size} m (the workspace_half_size)"
        )
        raise OutsideWorkspaceError(
            f"{files[0]}: push(es) {outside[:5].tolist()} leave the workspace, e.g. "
            f"{pushes[outside[0]].tolist()}; every coordinate must lie within {limit}. State the "
            "robot's real workspace in meta.json, or check the units and the table frame."
        )
    sizes = {path: _image_size(path) for path in frames}
    expected: tuple[int, int] = meta.image_size or sizes[frames[0]]
    wrong = [path for path, size in sizes.items() if size != expected]
    if wrong:
        raise FrameSizeError(
            f"{wrong[0]} is {sizes[wrong[0]][0]}x{sizes[wrong[0]][1]} px but "
            f"{'meta.json states' if meta.image_size else 'the first frame is'} "
            f"{expected[0]}x{expected[1]} px; every frame must have the same size."
        )
    return FolderEpisode(folder, frames, normalised.astype(np.float32), expected)


def read_push_folder(root: str | os.PathLike) -> PushFolder:
    """Reads and checks a whole push folder: its ``meta.json`` and every episode.

    Reads the pushes and the frames' headers (sizes), not the pixels.

    Raises:
        PushFolderError: The named error of the first problem found (see the subclasses).
    """
    root = Path(root)
    meta = FolderMeta.read(root)
    folders = sorted(
        path for path in root.iterdir() if path.is_dir() and EPISODE_PATTERN.fullmatch(path.name)
    )
    if not folders:
        raise NotPushFolderError(
            f"{root} holds no episode folders (episode_000000/, episode_000001/, ...: frames "
            "frame_000000.png, ... and a pushes file each; docs/data.md)."
        )
    episodes = tuple(read_episode(folder, meta) for folder in folders)
    sizes = sorted({episode.image_size for episode in episodes})
    if len(sizes) > 1:
        raise FrameSizeError(
            f"The episodes of {root} have frames of different sizes {sizes}; every frame must "
            "have the same size (state it as image_size in meta.json)."
        )
    return PushFolder(root, meta, episodes)
