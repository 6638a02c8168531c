"""TorchRL logger construction (CSV by default; TensorBoard or W&B selectable)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from torchrl.record.loggers import Logger
from torchrl.record.loggers.utils import get_logger

LOGGER_KINDS = ("csv", "tensorboard", "wandb")


def make_logger(
    kind: str,
    run_dir: str | Path,
    exp_name: str,
    state_dict: Mapping[str, Any] | None = None,
    wandb_kwargs: Mapping[str, Any] | None = None,
) -> Logger:
    """Builds a TorchRL logger writing under ``run_dir/logs``; ``state_dict`` resumes one."""
    if kind not in LOGGER_KINDS:
        raise ValueError(f"logger.kind={kind!r} is not one of {LOGGER_KINDS}.")
    logger = get_logger(
        kind,
        logger_name=str(Path(run_dir) / "logs"),
        experiment_name=exp_name,
        state_dict=state_dict,
        wandb_kwargs=dict(wandb_kwargs or {}),
    )
    assert logger is not None
    return logger
