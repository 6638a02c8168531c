"""Trained KINet weights shipped with the package, each with a model card.

A shipped model ``<name>`` is ``weights/<name>.pt`` (a :meth:`KINetWorldModel.save_checkpoint`
file, loaded with ``weights_only=True``) and ``weights/<name>.json``, its card: the command,
seed, data, hardware and wall time that trained it, its measured metrics, and ``check``, the
protocol and result of the keypoint-accuracy check on freshly collected episodes that
:func:`kinet_rl.pipeline.pretrained_keypoint_accuracy` repeats. Wherever a checkpoint path is
accepted (``python -m kinet_rl.plan --checkpoint``), ``pretrained:<name>`` names a shipped one.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

WEIGHTS_DIR = Path(__file__).resolve().with_name("weights")
PREFIX = "pretrained:"


def pretrained_names() -> list[str]:
    """Names of the shipped models."""
    return sorted(p.stem for p in WEIGHTS_DIR.glob("*.pt"))


def pretrained_path(name: str) -> Path:
    """The checkpoint file of shipped model ``name``."""
    path = WEIGHTS_DIR / f"{name}.pt"
    if not path.is_file():
        raise ValueError(
            f"No pretrained model {name!r}; shipped: {pretrained_names()} (or pass the path of a "
            "kinet.pt you trained)."
        )
    return path


def model_card(name: str) -> dict[str, Any]:
    """The model card of shipped model ``name`` (training command, data, metrics, check)."""
    return json.loads(pretrained_path(name).with_suffix(".json").read_text())


def resolve_checkpoint(checkpoint: str | Path) -> Path:
    """A checkpoint path, or the shipped file for ``"pretrained:<name>"``."""
    text = str(checkpoint)
    return pretrained_path(text[len(PREFIX) :]) if text.startswith(PREFIX) else Path(text)
