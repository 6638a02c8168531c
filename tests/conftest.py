"""Shared fixtures: tiny untrained models, random images and transitions, a trainer on a fixed
batch, the Hydra config folder, a full disk; and the ``ycb`` marker, which skips a test (or one
parameter of it) when no YCB assets are configured.

This file also puts ``tests/`` on ``sys.path`` (pytest's default ``prepend`` import mode inserts
the folder of a rootdir-level ``conftest.py``), so the helper modules beside it
(``fake_push_env``, ``toy_model_envs``) import by their plain names from any test.
"""

from __future__ import annotations

import errno
import itertools
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import torch
from tensordict import TensorDict

import kinet_rl.atomic
from kinet_rl.baselines import (
    FullStateInteractionModel,
    ImageForwardInverseModel,
    ImageForwardModel,
    ObjectInteractionModel,
    VCDNWorldModel,
    VisualInteractionModel,
)
from kinet_rl.configs import config_dir
from kinet_rl.envs.ycb import YCB_DIR_ENV
from kinet_rl.keys import ACTION, FUTURE_ACTION, FUTURE_PIXELS, PIXELS, PIXELS_0
from kinet_rl.models import KINetLoss, KINetWorldModel
from kinet_rl.training import TrainingCheckpoint
from kinet_rl.training.loggers import make_logger
from kinet_rl.training.loop import Trainer, TrainerSettings

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
BASELINES = ("forw", "forwinv", "in", "in_full", "visin", "vcdn")
#: Why a test marked ``ycb`` is skipped, and how to run it.
YCB_SKIP_REASON = (
    f"needs the YCB assets: set {YCB_DIR_ENV} to a folder of YCB meshes with its manifest.json "
    "(README, YCB assets) to run it"
)


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        f"ycb: needs the YCB assets (${YCB_DIR_ENV}); skipped when it is not set. Mark a test "
        "with @pytest.mark.ycb, or one parameter with pytest.param(..., marks=pytest.mark.ycb).",
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Skips the tests marked ``ycb`` when ``$KINET_RL_YCB_DIR`` is not set (CI sets it, and also
    runs the unit tests once without it)."""
    if os.environ.get(YCB_DIR_ENV):
        return
    skip = pytest.mark.skip(reason=YCB_SKIP_REASON)
    for item in items:
        if item.get_closest_marker("ycb") is not None:
            item.add_marker(skip)


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
    """Builds a tiny, untrained baseline by name (``forw``, ``forwinv``, ``in``, ``in_full``,
    ``visin``, ``vcdn``)."""

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
        if name in ("in", "in_full"):
            model_class = ObjectInteractionModel if name == "in" else FullStateInteractionModel
            return model_class(num_objects=num_objects, embed_dim=8, num_rounds=1, **small)
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


@pytest.fixture
def transition_batch(random_images: Callable[..., torch.Tensor]) -> Callable[..., TensorDict]:
    """A random ``[batch]`` of 16 px transitions as ``PushDataset.sample(batch, horizon=3)``
    draws them: ``I_0``, ``I_t``, the push, ``I_t+1`` and the two pushes and frames after it."""

    def make(batch: int = 8, seed: int = 0) -> TensorDict:
        frames = random_images((batch, 5), seed)
        gen = torch.Generator().manual_seed(seed)
        actions = torch.rand(batch, 3, 4, generator=gen) * 2 - 1
        return TensorDict(
            {
                PIXELS_0: frames[:, 0],
                PIXELS: frames[:, 1],
                ACTION: actions[:, 0],
                "next": {PIXELS: frames[:, 2]},
                FUTURE_PIXELS: frames[:, 3:],
                FUTURE_ACTION: actions[:, 1:],
            },
            batch_size=[batch],
        )

    return make


class FixedBatch:
    """A sampler that always draws the same batch."""

    def __init__(self, batch: TensorDict) -> None:
        self.batch = batch

    def sample(self, batch_size: int, generator: Any = None, **options: Any) -> TensorDict:
        assert batch_size == self.batch.shape[0]
        return self.batch


@pytest.fixture
def kinet_trainer(
    tmp_path: Path,
    tiny_kinet: Callable[..., KINetWorldModel],
    transition_batch: Callable[..., TensorDict],
) -> Callable[..., Trainer]:
    """``kinet_trainer(name, **settings)``: a Trainer of the tiny KINet (the same weights each
    call) with the rollout loss, on one fixed ``transition_batch()``, in ``tmp_path / name``."""
    batch = transition_batch()

    def make(name: str, **settings: Any) -> Trainer:
        data = FixedBatch(batch)
        return Trainer(
            KINetLoss(tiny_kinet(), rollout_weight=1.0),
            data,
            data,
            TrainerSettings(batch_size=batch.shape[0], horizon=3, **settings),
            TrainingCheckpoint(tmp_path / name, {"exp": "tiny kinet"}),
            make_logger("csv", tmp_path / name, name),
        )

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
