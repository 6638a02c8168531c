"""Shared fixtures: tiny untrained models, random images, the Hydra config folder, a full disk.

This file also puts ``tests/`` on ``sys.path`` (pytest's default ``prepend`` import mode inserts
the folder of a rootdir-level ``conftest.py``), so the helper modules beside it
(``fake_push_env``, ``toy_model_envs``) import by their plain names from any test.
"""

from __future__ import annotations

import errno
import itertools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import torch

import kinet_rl.atomic
from kinet_rl.baselines import (
    ImageForwardInverseModel,
    ImageForwardModel,
    ObjectInteractionModel,
    VCDNWorldModel,
    VisualInteractionModel,
)
from kinet_rl.configs import config_dir
from kinet_rl.models import KINetWorldModel

#: Constructor settings of the tiny KINet of the planning and rearrangement tests.
TINY_KINET = {
    "num_keypoints": 4,
    "feat_dim": 4,
    "channels": 8,
    "embed_dim": 8,
    "hidden_dim": 16,
    "num_hidden": 1,
    "num_rounds": 1,
}
#: Constructor settings of the tiny V-CDN of the baseline tests.
TINY_VCDN = {
    "num_keypoints": 4,
    "channels": 8,
    "embed_dim": 8,
    "hidden_dim": 16,
    "num_hidden": 1,
    "num_rounds": 2,
}
#: Baseline names understood by the ``tiny_baseline`` fixture.
BASELINES = ("forw", "forwinv", "in", "visin", "vcdn")


@pytest.fixture(scope="session")
def conf_dir() -> Path:
    """The ``conf/`` folder of the Hydra configs (``kinet_rl.configs.config_dir()``)."""
    return Path(config_dir())


@pytest.fixture
def tiny_kinet() -> Callable[..., KINetWorldModel]:
    """Builds a tiny, untrained KINet (``TINY_KINET`` with ``overrides``, in eval mode)."""

    def make(seed: int = 0, **overrides) -> KINetWorldModel:
        torch.manual_seed(seed)
        return KINetWorldModel(**{**TINY_KINET, **overrides}).eval()

    return make


@pytest.fixture
def tiny_baseline() -> Callable[..., torch.nn.Module]:
    """Builds a tiny, untrained baseline by name (``forw``, ``forwinv``, ``in``, ``visin``,
    ``vcdn``)."""

    def make(name: str, num_objects: int = 3, image_size: int = 32) -> torch.nn.Module:
        if name not in BASELINES:
            raise ValueError(f"Unknown baseline {name!r}; choose from {BASELINES}.")
        torch.manual_seed(0)
        small = {"hidden_dim": 16, "num_hidden": 1}
        if name in ("forw", "forwinv"):
            model_class = ImageForwardModel if name == "forw" else ImageForwardInverseModel
            return model_class(feature_dim=8, channels=4, probe_hidden_dim=8, **small)
        if name == "vcdn":
            return VCDNWorldModel(**TINY_VCDN)
        if name == "in":
            return ObjectInteractionModel(
                num_objects=num_objects, embed_dim=8, num_rounds=1, **small
            )
        return VisualInteractionModel(
            num_objects=num_objects, image_size=image_size, crop_size=8.0, crop_resolution=8,
            feat_dim=4, channels=4, embed_dim=8, num_rounds=1, **small,
        )  # fmt: skip

    return make


@pytest.fixture
def random_images() -> Callable[..., torch.Tensor]:
    """Random uint8 images ``[*batch, size, size, 3]``, reproducible by ``seed``."""

    def make(batch: tuple[int, ...], seed: int, size: int = 16) -> torch.Tensor:
        gen = torch.Generator().manual_seed(seed)
        return torch.randint(0, 256, (*batch, size, size, 3), generator=gen, dtype=torch.uint8)

    return make


class HalfWrittenFile:
    """A real file whose next ``write`` stores half its bytes and fails as on a full disk."""

    def __init__(self, file: Any) -> None:
        self.file = file

    def write(self, data: Any) -> int:
        self.file.write(data[: len(data) // 2])
        self.file.flush()
        raise OSError(errno.ENOSPC, "No space left on device")

    def __getattr__(self, name: str) -> Any:
        return getattr(self.file, name)

    def __enter__(self) -> HalfWrittenFile:
        return self

    def __exit__(self, *exc: object) -> None:
        self.file.close()


@pytest.fixture
def full_disk(monkeypatch: pytest.MonkeyPatch) -> Callable[[int], None]:
    """``full_disk(n)``: after ``n`` more files, every atomic write fails midway with ENOSPC."""

    def fill_after(files_that_fit: int) -> None:
        opened = itertools.count()

        def open_on_full_disk(file: Any, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
            handle = open(file, mode, *args, **kwargs)  # noqa: SIM115 (the caller closes it)
            return handle if next(opened) < files_that_fit else HalfWrittenFile(handle)

        monkeypatch.setattr(kinet_rl.atomic, "open", open_on_full_disk, raising=False)

    return fill_after
