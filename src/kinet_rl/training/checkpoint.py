"""Atomic, resumable training checkpoints."""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

import torch

log = logging.getLogger(__name__)


class CheckpointError(RuntimeError):
    """A checkpoint is missing, corrupt, truncated or does not match the run's config."""


def atomic_torch_save(obj: Any, path: str | os.PathLike) -> None:
    """Writes ``obj`` with ``torch.save`` to a temporary file, then renames it over ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as f:
        torch.save(obj, f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def safe_torch_load(path: str | os.PathLike) -> dict[str, Any]:
    """Loads a checkpoint with ``weights_only=True`` and turns failures into a clear error."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"No checkpoint at {path}.")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises several types for truncated/corrupt files
        raise CheckpointError(
            f"Checkpoint {path} is corrupt or truncated ({type(err).__name__}: {err}). "
            "Delete it to start the run afresh, or point to another checkpoint."
        ) from err
    if not isinstance(state, dict):
        raise CheckpointError(f"Checkpoint {path} does not hold a dict; it was not written by kinet_rl.")
    return state


class TrainingCheckpoint:
    """The run directory's resumable state: ``last.pt`` (latest good step) and ``best.pt``.

    A run that re-executes the same command finds ``last.pt`` and resumes from it. The stored
    ``config`` must equal the run's config on the keys that shape the model and data, otherwise
    resuming would silently mix two experiments.
    """

    def __init__(self, run_dir: str | os.PathLike, identity: dict[str, Any]) -> None:
        self.dir = Path(run_dir) / "checkpoints"
        self.identity = identity

    @property
    def last_path(self) -> Path:
        return self.dir / "last.pt"

    def save(self, state: dict[str, Any], *, best: bool = False) -> None:
        """Atomically writes ``state`` (plus the run identity) as the latest checkpoint."""
        state = {**state, "identity": self.identity}
        atomic_torch_save(state, self.last_path)
        if best:
            atomic_torch_save(state, self.dir / "best.pt")

    def load_latest(self) -> dict[str, Any] | None:
        """Returns the latest checkpoint of this run, or ``None`` when the run is new."""
        if not self.last_path.exists():
            return None
        state = safe_torch_load(self.last_path)
        stored = state.get("identity")
        if stored != self.identity:
            diff = sorted(
                k
                for k in set(self.identity) | set(stored or {})
                if (stored or {}).get(k) != self.identity.get(k)
            )
            raise CheckpointError(
                f"Checkpoint {self.last_path} belongs to a different experiment (differs in: "
                f"{', '.join(diff)}). Use a new run directory (hydra.run.dir=...) or delete it."
            )
        log.info("Resuming from %s (step %s)", self.last_path, state.get("step"))
        return state
