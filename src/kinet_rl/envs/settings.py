"""Typed scene settings: what a pushing scene is, as plain data that checkpoints and runs store."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from typing import Any


@dataclass(frozen=True)
class SceneSettings:
    """Arguments of :func:`kinet_rl.envs.make_dm_env` that define a scene (not its seed)."""

    task: str = "blocks"
    num_objects: int = 3
    camera: str = "top"
    image_size: int = 64
    geometry: str = "train"
    background: str = "fixed"

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> SceneSettings:
        """The scene of an env config (extra keys such as ``seed`` or ``max_steps`` are ignored)."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in values.items() if k in names})

    def as_dict(self) -> dict[str, Any]:
        """Plain-container form (for JSON and checkpoints)."""
        return asdict(self)
