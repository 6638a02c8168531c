"""Finished rearrangement episodes on disk, so that an interrupted evaluation resumes.

Each finished episode is written atomically to ``<dir>/<fingerprint>/<name>.npz`` (the runner
names episodes ``<condition>/<method>/seed<seed>``); the fingerprint hashes the evaluation
settings that shape an episode and the model (class, config and weights), so episodes of another
model or other settings are never reused. Rerunning the evaluation loads the stored episodes and
runs only the missing ones (each episode depends only on its seed: the results are those of an
uninterrupted run), also with more episodes, other methods or cells, or another worker count.
"""

from __future__ import annotations

import hashlib
import json
import logging
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from kinet_rl.atomic import atomic_save_with
from kinet_rl.rearrangement.results import EpisodeResult
from kinet_rl.rearrangement.settings import RearrangementSettings

logger = logging.getLogger(__name__)


# Settings that choose which episodes run, or where, but not what one episode does: left out of
# the fingerprint so that a rerun with more episodes or workers reuses the finished ones.
SELECTION_SETTINGS = (
    "episodes",
    "methods",
    "num_objects",
    "geometries",
    "backgrounds",
    "generalization_episodes",
    "workers",
)


def fingerprint(settings: RearrangementSettings, model: torch.nn.Module | None) -> str:
    """A short hash of the episode-shaping settings and of the model's class, config and weights."""
    shaping = {k: v for k, v in settings.as_dict().items() if k not in SELECTION_SETTINGS}
    digest = hashlib.sha256(json.dumps(shaping, sort_keys=True).encode())
    if model is not None:
        config = model.config
        digest.update(f"{type(model).__qualname__}{json.dumps(config, sort_keys=True)}".encode())
        for name, tensor in model.state_dict().items():
            digest.update(name.encode())
            digest.update(tensor.detach().cpu().contiguous().numpy().tobytes())
    return digest.hexdigest()[:16]


def episode_arrays(result: EpisodeResult) -> dict[str, np.ndarray]:
    """The arrays that :func:`episode_from_arrays` turns back into ``result``."""
    arrays = {
        "method": np.array(result.method),
        "seed": np.array(result.seed),
        "distances": np.asarray(result.distances),
        "success": np.array(result.success),
        "unstable": np.array(result.unstable),
    }
    if result.goal_ssim is not None:
        arrays["goal_ssim"] = np.asarray(result.goal_ssim)
    if result.frames:
        arrays["frames"] = np.stack(result.frames)
    if result.keypoints:
        arrays["keypoints"] = np.stack(result.keypoints)
    if result.goal_pixels is not None:
        arrays["goal_pixels"] = np.asarray(result.goal_pixels)
    if result.goal_keypoints is not None:
        arrays["goal_keypoints"] = np.asarray(result.goal_keypoints)
    return arrays


def episode_from_arrays(arrays: Mapping[str, np.ndarray]) -> EpisodeResult:
    """The :class:`EpisodeResult` stored by :func:`episode_arrays`."""
    return EpisodeResult(
        method=str(arrays["method"]),
        seed=int(arrays["seed"]),
        distances=arrays["distances"],
        success=bool(arrays["success"]),
        unstable=bool(arrays["unstable"]),
        goal_ssim=arrays.get("goal_ssim"),
        frames=list(arrays.get("frames", [])),
        keypoints=list(arrays.get("keypoints", [])),
        goal_pixels=arrays.get("goal_pixels"),
        goal_keypoints=arrays.get("goal_keypoints"),
    )


class EpisodeStore:
    """The finished episodes of one evaluation (settings and model) under ``directory``.

    Args:
        directory: Folder of the stores of all evaluations written there.
        settings: The evaluation's settings.
        model: The evaluated model (None for model-free methods).
    """

    def __init__(
        self, directory: Path, settings: RearrangementSettings, model: torch.nn.Module | None
    ) -> None:
        self.dir = Path(directory) / fingerprint(settings, model)

    def load(self, name: str) -> EpisodeResult | None:
        """The stored episode ``name``, or None if it has not finished (or is unreadable)."""
        path = self.dir / f"{name}.npz"
        if not path.is_file():
            return None
        try:
            with np.load(path, allow_pickle=False) as arrays:
                return episode_from_arrays({key: arrays[key] for key in arrays.files})
        except (OSError, ValueError, KeyError, zipfile.BadZipFile) as err:
            logger.warning("Ignoring unreadable episode %s (%s); it runs again.", path, err)
            return None

    def save(self, name: str, result: EpisodeResult) -> None:
        """Writes the finished episode ``name`` atomically."""
        arrays: dict[str, Any] = episode_arrays(result)  # Any: savez's stubs reject ndarray
        atomic_save_with(self.dir / f"{name}.npz", lambda f: np.savez(f, **arrays))
