"""Atomic, resumable training checkpoints."""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

from kinet_rl.atomic import CheckpointError, atomic_torch_save, safe_torch_load

log = logging.getLogger(__name__)


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
