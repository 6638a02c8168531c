"""Typed scene settings: what a pushing scene is, as plain data that checkpoints and runs store."""

from __future__ import annotations

import numbers
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from kinet_rl.config_schema import require, settings_from
from kinet_rl.envs.blocks import BLOCK_SIZE_RANGES
from kinet_rl.envs.frames import square_array
from kinet_rl.envs.scene import CAMERAS
from kinet_rl.envs.workspace import workspace_for

TASKS = ("blocks", "ycb")
MAX_OBJECTS = 5
BACKGROUNDS = ("fixed", "random")
#: Block geometries: ``train`` sizes and elongated out-of-distribution ``gen`` ones.
GEOMETRIES = tuple(BLOCK_SIZE_RANGES)
#: Smallest image side: the keypoint detector works on features at 1/4 resolution.
MIN_IMAGE_SIZE = 16


def _is_integer(value: Any) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def check_image_size(image_size: Any, key: str = "image_size") -> None:
    """Raises ``ConfigError`` unless ``image_size`` is a multiple of 4 of at least 16 pixels."""
    require(
        _is_integer(image_size) and image_size % 4 == 0 and image_size >= MIN_IMAGE_SIZE,
        key,
        image_size,
        f"a multiple of 4 of at least {MIN_IMAGE_SIZE} pixels (e.g. 32, 64)",
    )


@dataclass(frozen=True)
class SceneSettings:
    """Arguments of :func:`kinet_rl.envs.make_dm_env` that define a scene (not its seed).

    Raises:
        ConfigError: A value out of range (e.g. ``num_objects`` outside 1-5), naming it.
    """

    task: str = "blocks"
    num_objects: int = 3
    camera: str = "top"
    image_size: int = 64
    geometry: str = "train"
    background: str = "fixed"
    #: The YCB objects to draw from, by name (``None``: every object of the manifest). A scene
    #: of held-out objects differs from the training scene only here.
    ycb_objects: tuple[str, ...] | None = None
    #: Half the side of the square workspace, metres, where it is not the task's: a robot's
    #: dataset (``python -m kinet_rl.import_data``) states its own. None: the task's (0.20 m
    #: blocks, 0.30 m YCB); see :attr:`half_size`.
    workspace_half_size: float | None = None
    #: A robot camera's frame size ``(width, height)`` and the square ``(left, top, size)`` of it
    #: that an import kept (then resized to :attr:`image_size`): :meth:`model_frame` applies the
    #: same to a live frame. None: frames are already the model's images (simulated scenes).
    source_image_size: tuple[int, int] | None = None
    crop_box: tuple[int, int, int] | None = None

    def __post_init__(self) -> None:
        for name, choices in (
            ("task", TASKS),
            ("camera", CAMERAS),
            ("geometry", GEOMETRIES),
            ("background", BACKGROUNDS),
        ):
            value = getattr(self, name)
            require(value in choices, name, value, f"one of {list(choices)}")
        require(
            _is_integer(self.num_objects) and 1 <= self.num_objects <= MAX_OBJECTS,
            "num_objects",
            self.num_objects,
            f"an integer from 1 to {MAX_OBJECTS}",
        )
        check_image_size(self.image_size)
        if self.ycb_objects is not None:
            require(self.task == "ycb", "ycb_objects", self.ycb_objects, "null for task blocks")
            require(
                len(self.ycb_objects) > 0,
                "ycb_objects",
                self.ycb_objects,
                "null (every object) or a non-empty list of YCB object names",
            )
        if self.workspace_half_size is not None:
            require(
                isinstance(self.workspace_half_size, numbers.Real)
                and not isinstance(self.workspace_half_size, bool)
                and 0 < self.workspace_half_size < float("inf"),
                "workspace_half_size",
                self.workspace_half_size,
                "null (the task's workspace) or metres > 0",
            )
        if self.crop_box is not None or self.source_image_size is not None:
            width, height = self.source_image_size or (0, 0)
            left, top, size = self.crop_box or (0, 0, 0)
            require(
                size >= 1 and min(left, top) >= 0 and left + size <= width and top + size <= height,
                "crop_box",
                self.crop_box,
                f"a square (left, top, size) inside the source frames {self.source_image_size}, "
                "both given or neither",
            )

    @property
    def half_size(self) -> float:
        """Half the side of the workspace in metres: :attr:`workspace_half_size` where given,
        else the task's (:func:`~kinet_rl.envs.workspace.workspace_for`)."""
        if self.workspace_half_size is not None:
            return float(self.workspace_half_size)
        return workspace_for(self.task).half_size

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> SceneSettings:
        """The scene of an env config (extra keys such as ``seed`` or ``max_steps`` are ignored)."""
        names = {f.name for f in fields(cls)}
        return settings_from(cls, {k: v for k, v in values.items() if k in names})

    def as_dict(self) -> dict[str, Any]:
        """Plain-container form (for JSON and checkpoints); a robot's workspace and frame crop
        only where given, so a simulated scene's form is also
        :func:`~kinet_rl.envs.make_env`'s arguments."""
        values = asdict(self)
        for name in ("workspace_half_size", "source_image_size", "crop_box"):
            if values[name] is None:
                del values[name]
        return values

    def model_frame(self, frame: np.ndarray) -> np.ndarray:
        """An RGB uint8 ``[H, W, 3]`` camera frame as the model's image: a frame of the source
        camera's size is cropped and resized as its import did; other frames pass unchanged."""
        if self.crop_box is None or self.source_image_size is None:
            return frame
        if (frame.shape[1], frame.shape[0]) != tuple(self.source_image_size):
            return frame
        return square_array(frame, self.crop_box, self.image_size)
