"""Trained models shipped with the package, and where ``from_pretrained`` finds a model.

A shipped model ``<name>`` is the model folder ``weights/<name>/`` (Hugging Face layout, see
:mod:`kinet_rl.models.hub`: ``model.safetensors``, ``config.json``, ``README.md``). Its card
(:func:`model_card`) gives the command, seed, data, hardware and wall time that trained it, its
measured metrics, and ``check``, the protocol and result of the keypoint-accuracy check on
freshly collected episodes that :func:`kinet_rl.pipeline.pretrained_keypoint_accuracy` repeats.
Wherever a checkpoint path is accepted (``python -m kinet_rl.plan --checkpoint``),
``pretrained:<name>`` names a shipped one. Shipped models load offline.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

from kinet_rl.models.hub import download, is_model_folder, read_card

WEIGHTS_DIR = Path(__file__).resolve().with_name("weights")
PREFIX = "pretrained:"
#: A Hugging Face Hub repo id, ``owner/name``.
HUB_REPO_ID = re.compile(r"[A-Za-z0-9][\w.-]*/[\w.-]+")


def pretrained_names() -> list[str]:
    """Names of the shipped models."""
    return sorted(p.name for p in WEIGHTS_DIR.iterdir() if is_model_folder(p))


def pretrained_path(name: str) -> Path:
    """The model folder of shipped model ``name``."""
    path = WEIGHTS_DIR / name
    if not name or "/" in name or not is_model_folder(path):
        raise ValueError(
            f"No pretrained model {name!r}; shipped: {pretrained_names()} (or pass the path of a "
            "kinet.pt or model folder you trained)."
        )
    return path


def model_card(name: str) -> dict[str, Any]:
    """The model card of shipped model ``name`` (training command, data, metrics, check)."""
    return read_card(pretrained_path(name))


def resolve_checkpoint(checkpoint: str | Path) -> Path:
    """A checkpoint path (a ``.pt`` file or a model folder), or the shipped model's folder for
    ``"pretrained:<name>"``."""
    text = str(checkpoint)
    return pretrained_path(text[len(PREFIX) :]) if text.startswith(PREFIX) else Path(text)


def model_folder(
    name_or_folder: str | os.PathLike, revision: str | None = None, token: str | None = None
) -> Path:
    """The model folder ``from_pretrained`` loads: a local folder, a shipped model (by name or
    ``pretrained:<name>``), or a Hugging Face Hub repo id ``owner/name`` (downloaded into the
    Hub cache; needs ``kinet_rl[hub]``).

    Raises:
        ValueError: Neither a local path, a shipped name nor a repo id (lists the shipped ones).
        HubExtraMissingError: A repo id without ``huggingface_hub`` installed.
    """
    path = Path(name_or_folder)
    text = str(name_or_folder)
    if path.exists():
        return path
    if text.startswith(PREFIX) or text in pretrained_names():
        return pretrained_path(text.removeprefix(PREFIX))
    if HUB_REPO_ID.fullmatch(text):
        return download(text, revision=revision, token=token)
    raise ValueError(
        f"{text!r} is no local folder, no shipped model ({pretrained_names()}) and no Hugging "
        "Face Hub repo id (owner/name)."
    )
