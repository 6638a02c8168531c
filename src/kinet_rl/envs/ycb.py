"""YCB object folders described by ``manifest.json``: loading and validation.

A folder holds ``manifest.json`` with an ``objects`` list; each entry names its visual mesh,
texture, convex collision meshes, collision density and resting half extents (metres, +z up,
identity orientation = stable resting pose, body origin = bounding-box centre).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["YCB_DIR_ENV", "YcbObject", "YcbManifestError", "resolve_ycb_dir", "load_ycb_objects"]

YCB_DIR_ENV = "KINET_RL_YCB_DIR"
_HOW_TO_GET = (
    "Obtain the YCB object and model set from https://www.ycbbenchmarks.com (models, e.g. the "
    "google_16k meshes), convert each object to a folder with visual.obj, texture.png and convex "
    "collision_NN.obj meshes, and describe them in manifest.json (see the kinet_rl docs for the "
    f"format); then pass ycb_dir=... or set the environment variable {YCB_DIR_ENV}."
)
_REQUIRED_KEYS = (
    "name",
    "visual_mesh",
    "texture",
    "collision_meshes",
    "collision_density_kg_m3",
    "half_extents_m",
)


class YcbManifestError(ValueError):
    """The YCB asset folder is missing or its ``manifest.json`` is malformed."""


@dataclass(frozen=True)
class YcbObject:
    """One YCB object, with absolute file paths.

    Attributes:
        name: unique object name, e.g. ``"003_cracker_box"``.
        visual_mesh: OBJ file of the textured visual mesh.
        texture: PNG texture of the visual mesh.
        collision_meshes: convex OBJ collision meshes.
        density: collision density in kg / m^3 (total mass = YCB mass).
        half_extents: ``[3]`` bounding-box half extents in the resting pose, metres.
    """

    name: str
    visual_mesh: Path
    texture: Path
    collision_meshes: tuple[Path, ...]
    density: float
    half_extents: np.ndarray

    @property
    def rest_height(self) -> float:
        """Height of the body origin above the table top when resting."""
        return float(self.half_extents[2])


def resolve_ycb_dir(ycb_dir: str | os.PathLike | None) -> Path:
    """Return the YCB folder from ``ycb_dir`` or, if ``None``, the ``KINET_RL_YCB_DIR`` variable."""
    if ycb_dir is None:
        ycb_dir = os.environ.get(YCB_DIR_ENV)
        if not ycb_dir:
            raise YcbManifestError(
                f"No YCB asset folder given and {YCB_DIR_ENV} is not set. {_HOW_TO_GET}"
            )
    path = Path(ycb_dir).expanduser()
    if not (path / "manifest.json").is_file():
        raise YcbManifestError(f"YCB asset folder {path} has no manifest.json. {_HOW_TO_GET}")
    return path


def _parse_entry(root: Path, index: int, entry: object) -> YcbObject:
    if not isinstance(entry, dict):
        raise YcbManifestError(
            f"{root}/manifest.json: objects[{index}] must be an object, got {type(entry).__name__}."
        )
    missing = [key for key in _REQUIRED_KEYS if key not in entry]
    if missing:
        raise YcbManifestError(
            f"{root}/manifest.json: objects[{index}] lacks {missing}; every entry needs {list(_REQUIRED_KEYS)}."
        )
    name = entry["name"]
    collision = entry["collision_meshes"]
    if not isinstance(collision, list) or not collision:
        raise YcbManifestError(
            f"{root}/manifest.json: {name}: collision_meshes must be a non-empty list of files."
        )
    half = np.asarray(entry["half_extents_m"], dtype=float)
    if half.shape != (3,) or np.any(half <= 0):
        raise YcbManifestError(
            f"{root}/manifest.json: {name}: half_extents_m must be 3 positive numbers, got {half.tolist()}."
        )
    density = float(entry["collision_density_kg_m3"])
    if density <= 0:
        raise YcbManifestError(
            f"{root}/manifest.json: {name}: collision_density_kg_m3 must be positive."
        )
    files = [entry["visual_mesh"], entry["texture"], *collision]
    absent = [f for f in files if not (root / f).is_file()]
    if absent:
        raise YcbManifestError(
            f"{root}/manifest.json: {name}: files not found: {absent}. {_HOW_TO_GET}"
        )
    return YcbObject(
        name=name,
        visual_mesh=(root / entry["visual_mesh"]).resolve(),
        texture=(root / entry["texture"]).resolve(),
        collision_meshes=tuple((root / f).resolve() for f in collision),
        density=density,
        half_extents=half,
    )


def load_ycb_objects(
    ycb_dir: str | os.PathLike | None = None, names: Sequence[str] | None = None
) -> list[YcbObject]:
    """Load and validate the objects of a YCB folder, optionally only those in ``names``.

    Raises:
        YcbManifestError: the folder or manifest is missing or malformed, a listed file is
            absent, or a requested name is not in the manifest.
    """
    root = resolve_ycb_dir(ycb_dir)
    try:
        manifest = json.loads((root / "manifest.json").read_text())
    except json.JSONDecodeError as err:
        raise YcbManifestError(
            f"{root}/manifest.json is not valid JSON ({err}). {_HOW_TO_GET}"
        ) from None
    entries = manifest.get("objects") if isinstance(manifest, dict) else None
    if not isinstance(entries, list) or not entries:
        raise YcbManifestError(
            f"{root}/manifest.json needs a non-empty 'objects' list. {_HOW_TO_GET}"
        )
    objects = [_parse_entry(root, i, entry) for i, entry in enumerate(entries)]
    if names is None:
        return objects
    by_name = {obj.name: obj for obj in objects}
    unknown = [n for n in names if n not in by_name]
    if unknown:
        raise YcbManifestError(
            f"Unknown YCB objects {unknown} in {root}; available: {sorted(by_name)}."
        )
    return [by_name[n] for n in names]
