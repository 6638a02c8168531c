"""Shared fixtures: tiny untrained models, random images and the Hydra config folder.

This file also puts ``tests/`` on ``sys.path`` (pytest's default ``prepend`` import mode inserts
the folder of a rootdir-level ``conftest.py``), so the helper modules beside it
(``fake_push_env``, ``toy_model_envs``) import by their plain names from any test.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
import torch

from kinet_rl.baselines import (
    ImageForwardInverseModel,
    ImageForwardModel,
    ObjectInteractionModel,
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
#: Baseline names understood by the ``tiny_baseline`` fixture.
BASELINES = ("forw", "forwinv", "in", "visin")


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
    """Builds a tiny, untrained baseline by name (``forw``, ``forwinv``, ``in``, ``visin``)."""

    def make(name: str, num_objects: int = 3, image_size: int = 32) -> torch.nn.Module:
        if name not in BASELINES:
            raise ValueError(f"Unknown baseline {name!r}; choose from {BASELINES}.")
        torch.manual_seed(0)
        small = {"hidden_dim": 16, "num_hidden": 1}
        if name in ("forw", "forwinv"):
            model_class = ImageForwardModel if name == "forw" else ImageForwardInverseModel
            return model_class(feature_dim=8, channels=4, probe_hidden_dim=8, **small)
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
