"""Training utilities: resumable checkpoints, loggers, image summaries and the training loop."""

from __future__ import annotations

from kinet_rl.training.checkpoint import CheckpointError, TrainingCheckpoint

__all__ = ["CheckpointError", "TrainingCheckpoint"]
