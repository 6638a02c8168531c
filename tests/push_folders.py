"""Small plain push folders (:mod:`kinet_rl.data.push_folder`) for the import and recorder tests."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from kinet_rl.data.recorder import PushRecorder

#: The workspace half size (metres) of the folders written here.
HALF_SIZE = 0.25


def frame(seed: int, width: int = 40, height: int = 32) -> np.ndarray:
    """A random RGB uint8 frame ``[height, width, 3]``."""
    return np.random.default_rng(seed).integers(0, 256, (height, width, 3), dtype=np.uint8)


def write_push_folder(
    root: Path,
    episodes: int = 6,
    frames: int = 5,
    width: int = 40,
    height: int = 32,
    seed: int = 0,
) -> Path:
    """Records ``episodes`` episodes of ``frames`` random frames and random pushes (metres,
    inside the workspace) with :class:`PushRecorder`; returns ``root``."""
    rng = np.random.default_rng(seed)
    recorder = PushRecorder(root, HALF_SIZE, camera="test_camera")
    for episode in range(episodes):
        for step in range(frames - 1):
            push = rng.uniform(-HALF_SIZE, HALF_SIZE, 4)
            recorder.append(frame(1000 * episode + step, width, height), push)
        recorder.close_episode(frame(1000 * episode + frames - 1, width, height))
    return root


def rewrite_pushes_csv(episode: Path, rows: list[list[str]], header: str | None = None) -> None:
    """Replaces an episode's ``pushes.csv`` with ``rows`` (strings, written as given)."""
    lines = [header or "start_x,start_y,end_x,end_y", *(",".join(row) for row in rows)]
    (episode / "pushes.csv").write_text("\n".join(lines) + "\n")


def edit_meta(root: Path, **entries: object) -> None:
    """Sets (None: removes) entries of a folder's ``meta.json``."""
    meta = json.loads((root / "meta.json").read_text())
    for key, value in entries.items():
        if value is None:
            meta.pop(key, None)
        else:
            meta[key] = value
    (root / "meta.json").write_text(json.dumps(meta))
