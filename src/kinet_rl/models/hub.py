"""Model folders in the Hugging Face layout, and their upload to and download from the Hub.

A model folder holds three files: ``model.safetensors`` (the state dict), ``config.json`` (the
model's checkpoint format, constructor config, scene and planning defaults: what
:meth:`~kinet_rl.models.checkpointing.ConfigCheckpointMixin.save_checkpoint` stores beside the
weights) and ``README.md``, its model card: YAML front matter (``library_name: kinet_rl``,
``license``, ``tags`` and, under ``kinet_rl``, the card's facts: training command, data, seed,
hardware, wall time, metrics, intended use, limits) and the same facts as Markdown. A folder is
written atomically (into a temporary folder beside it, then renamed), and never into a folder
that holds files. The Hub needs the optional ``huggingface_hub`` (``pip install 'kinet_rl[hub]'``);
nothing here touches the network unless a Hub repo id is named.
"""

from __future__ import annotations

import errno
import importlib
import json
import os
import shutil
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
import yaml
from safetensors import SafetensorError
from safetensors.torch import load as load_safetensors
from safetensors.torch import save as save_safetensors
from torch import Tensor

from kinet_rl.atomic import (
    CheckpointError,
    atomic_write,
    atomic_write_json,
    atomic_write_text,
)

CONFIG_FILE = "config.json"
WEIGHTS_FILE = "model.safetensors"
CARD_FILE = "README.md"
#: The files of a model folder (what a Hub download fetches).
MODEL_FILES = (CONFIG_FILE, WEIGHTS_FILE, CARD_FILE)
#: Entries every ``config.json`` holds.
CONFIG_ENTRIES = ("format", "model_config")
#: Tags of every card (the Hub lists models by them).
TAGS = ("kinet_rl", "torchrl", "robotics", "world-model", "model-based-rl", "pushing")
#: How the card's Markdown titles its sections (other entries: the key, capitalised).
HEADINGS = {
    "command": "Training command",
    "planning": "Planning objective and budget",
    "metrics": "Test metrics",
    "check": "Check on fresh episodes",
    "intended_use": "Intended use",
}
INSTALL_HUB = "pip install 'kinet_rl[hub]'"


class ModelFolderExistsError(FileExistsError):
    """``save_pretrained`` was pointed at a folder that already holds files (or at a file)."""


class NotAModelFolderError(CheckpointError):
    """A path given as a model folder lacks ``config.json`` or ``model.safetensors``."""


class ModelSceneError(CheckpointError):
    """A model's config or card names a scene that cannot be built (``SceneSettings``)."""


class ModelCardError(ValueError):
    """A model card contradicts the model it describes, or is not plain JSON-like data."""


class HubExtraMissingError(ImportError):
    """The Hugging Face Hub was asked for without the optional ``huggingface_hub`` installed."""


def is_model_folder(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a folder with ``config.json`` and ``model.safetensors``."""
    path = Path(path)
    return (path / CONFIG_FILE).is_file() and (path / WEIGHTS_FILE).is_file()


def plain(value: Any, what: str) -> Any:
    """``value`` as JSON gives it back (tuples become lists).

    Raises:
        ModelCardError: ``value`` holds something JSON cannot store.
    """
    try:
        return json.loads(json.dumps(value))
    except (TypeError, ValueError) as err:
        raise ModelCardError(
            f"The {what} must hold only JSON data (numbers, strings, lists, mappings): {err}."
        ) from None


def write_model_folder(
    folder: str | os.PathLike,
    config: Mapping[str, Any],
    state_dict: Mapping[str, Tensor],
    card: str,
) -> Path:
    """Writes a model folder atomically: all three files appear at once, or none.

    Args:
        folder: The folder to create (it may exist if empty).
        config: ``config.json``'s entries.
        state_dict: The weights (copied to contiguous CPU tensors).
        card: ``README.md``'s text (:func:`card_text`).

    Raises:
        ModelFolderExistsError: ``folder`` holds files or is a file; nothing is written.
        DiskFullError: The disk filled up; nothing is left behind.
    """
    folder = Path(folder).absolute()
    _refuse_existing(folder)
    tensors = {
        name: value.detach().cpu().clone(memory_format=torch.contiguous_format)
        for name, value in state_dict.items()
    }
    weights = save_safetensors(tensors, metadata={"format": "pt"})
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = folder.with_name(f".{folder.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
    tmp.mkdir()
    try:
        atomic_write_json(tmp / CONFIG_FILE, config)
        with atomic_write(tmp / WEIGHTS_FILE) as f:
            f.write(weights)
        atomic_write_text(tmp / CARD_FILE, card)
        try:
            os.replace(tmp, folder)  # onto nothing or an empty folder
        except OSError as err:
            if err.errno in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR, errno.EISDIR):
                _refuse_existing(folder)  # filled meanwhile: the named error
            raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    _fsync_dir(folder.parent)
    return folder


def _refuse_existing(folder: Path) -> None:
    if folder.is_dir() and not any(folder.iterdir()):
        return
    if folder.exists():
        raise ModelFolderExistsError(
            errno.EEXIST,
            f"Cannot save a model into {folder}: it "
            f"{'holds files' if folder.is_dir() else 'is a file'}, and saving would mix or "
            "overwrite them. Choose a new (or empty) folder, or delete this one first.",
        )


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def read_model_config(folder: str | os.PathLike) -> dict[str, Any]:
    """``config.json`` of a model folder (format, model config, scene, planning).

    Raises:
        NotAModelFolderError: ``folder`` lacks ``config.json`` or ``model.safetensors``.
        CheckpointError: ``config.json`` is not JSON or lacks ``format`` or ``model_config``.
    """
    folder = Path(folder)
    if not is_model_folder(folder):
        missing = [name for name in (CONFIG_FILE, WEIGHTS_FILE) if not (folder / name).is_file()]
        what = "does not exist" if not folder.exists() else f"lacks {' and '.join(missing)}"
        raise NotAModelFolderError(
            f"{folder} is not a kinet_rl model folder: it {what}. A model folder is written by "
            "save_pretrained (config.json, model.safetensors, README.md); a .pt checkpoint of a "
            "run loads with from_checkpoint or kinet_rl.rows.load_trained_model."
        )
    path = folder / CONFIG_FILE
    try:
        config = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise CheckpointError(
            f"{path} is not valid JSON ({err}); the folder was edited or damaged, save it again."
        ) from None
    if not isinstance(config, dict) or any(key not in config for key in CONFIG_ENTRIES):
        raise CheckpointError(
            f"{path} lacks the entries {list(CONFIG_ENTRIES)}; it was not written by "
            "save_pretrained."
        )
    return config


def read_model_weights(folder: str | os.PathLike) -> dict[str, Tensor]:
    """The state dict of a model folder (``model.safetensors``; no code is run).

    Raises:
        CheckpointError: The file is corrupt or truncated.
    """
    path = Path(folder) / WEIGHTS_FILE
    try:
        return load_safetensors(path.read_bytes())
    except (SafetensorError, ValueError, RuntimeError) as err:
        raise CheckpointError(
            f"{path} is corrupt or truncated and could not be read ({err}); download or save "
            "the model again."
        ) from None


def card_text(card: Mapping[str, Any], license_id: str = "mit") -> str:
    """``README.md`` of a model: YAML front matter (the Hub's metadata, and ``card`` itself
    under ``kinet_rl``) and ``card`` as Markdown sections."""
    card = plain(card, "model card")
    front = {"library_name": "kinet_rl", "license": license_id, "tags": list(TAGS)}
    lines = ["---", yaml.safe_dump({**front, "kinet_rl": card}, sort_keys=False).rstrip(), "---"]
    lines += ["", f"# {card.get('name', card.get('model', 'kinet_rl model'))}", ""]
    if card.get("description"):
        lines += [str(card["description"]), ""]
    lines += _usage(str(card.get("model", "")))
    for key, value in card.items():
        if key in ("name", "description"):
            continue
        heading = HEADINGS.get(key, key.replace("_", " ").capitalize())
        lines += [f"## {heading}", "", *_markdown(value), ""]
    return "\n".join(lines)


def _usage(model_class: str) -> list[str]:
    load = f"{model_class}.from_pretrained" if model_class else "load_trained_model"
    return [
        "## How to load",
        "",
        "```python",
        "from kinet_rl.rows import load_trained_model",
        "",
        'model = load_trained_model("path/to/this/folder")  # the class from config.json',
        f'# or {load}("<shipped name, this folder, or a Hub repo id>")',
        "```",
        "",
        "Plan a push from a camera image and a goal image (a model that plans from images): "
        "`python -m kinet_rl.plan --checkpoint path/to/this/folder --image now.png --goal "
        "goal.png`.",
        "",
    ]


def _markdown(value: Any, depth: int = 0) -> list[str]:
    """``value`` as Markdown: mappings and lists as (nested) bullets, scalars as text."""
    indent = "  " * depth
    if isinstance(value, Mapping):
        lines = []
        for key, item in value.items():
            if isinstance(item, (Mapping, list)):
                lines += [f"{indent}- {key}:", *_markdown(item, depth + 1)]
            else:
                lines.append(f"{indent}- {key}: {_scalar(item)}")
        return lines
    if isinstance(value, list):
        return [f"{indent}- {_scalar(item)}" for item in value]
    return [f"{indent}{_scalar(value)}"]


def _scalar(value: Any) -> str:
    return (
        "null" if value is None else str(value).lower() if isinstance(value, bool) else str(value)
    )


def read_card(folder: str | os.PathLike) -> dict[str, Any]:
    """The card facts of a model folder (the ``kinet_rl`` entry of its README's front matter;
    empty when it has no card).

    Raises:
        ModelCardError: The front matter is not valid YAML.
    """
    path = Path(folder) / CARD_FILE
    if not path.is_file():
        return {}
    text = path.read_text()
    if not text.startswith("---\n"):
        return {}
    end = text.find("\n---\n", 4)
    try:
        front = yaml.safe_load(text[4:end]) if end > 0 else None
    except yaml.YAMLError as err:
        raise ModelCardError(f"{path}'s front matter is not valid YAML: {err}") from None
    card = front.get("kinet_rl") if isinstance(front, dict) else None
    return dict(card) if isinstance(card, dict) else {}


def huggingface_hub(purpose: str) -> Any:
    """The ``huggingface_hub`` module.

    Raises:
        HubExtraMissingError: It is not installed (the error says how to install it).
    """
    try:
        return importlib.import_module("huggingface_hub")
    except ImportError:
        raise HubExtraMissingError(
            f"{purpose} needs the Hugging Face Hub client, an optional extra: {INSTALL_HUB}. "
            "Shipped models and local model folders load without it."
        ) from None


def download(repo_id: str, revision: str | None = None, token: str | None = None) -> Path:
    """Downloads (or finds in the Hub cache) the model folder of Hub repo ``repo_id``."""
    hub = huggingface_hub(
        f"Loading {repo_id!r} (no local folder of that name) from the Hugging Face Hub"
    )
    path = hub.snapshot_download(
        repo_id, revision=revision, token=token, allow_patterns=list(MODEL_FILES),
        library_name="kinet_rl",
    )  # fmt: skip
    return Path(path)


def upload_folder(
    folder: str | os.PathLike,
    repo_id: str,
    *,
    private: bool | None = None,
    token: str | None = None,
    commit_message: str = "Upload kinet_rl model",
) -> Any:
    """Creates Hub repo ``repo_id`` if needed and uploads a model folder to it; returns the
    Hub's commit info."""
    hub = huggingface_hub(f"Uploading to {repo_id!r} on the Hugging Face Hub")
    api = hub.HfApi(token=token)
    api.create_repo(repo_id, private=private, exist_ok=True)
    return api.upload_folder(
        repo_id=repo_id, folder_path=str(folder), commit_message=commit_message
    )
