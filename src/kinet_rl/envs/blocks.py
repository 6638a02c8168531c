"""BlockObjs geometry: each object is two cuboids rigidly joined into an L, T or I shape.

Per-episode sizes are written into the compiled model (``geom_size``, ``geom_pos``) and the
body's mass properties are made consistent with them: the composite mass, centre of mass and
inertia tensor are computed in closed form (box inertia + parallel-axis theorem), the geoms are
shifted so that the centre of mass is the body origin (so ``object_pos`` is the COM), and the
inertia tensor is diagonalised into ``body_inertia`` and ``body_iquat``.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

__all__ = [
    "BLOCK_SIZE_RANGES",
    "BLOCK_DENSITY",
    "BLOCK_HALF_HEIGHT",
    "BlockGeometry",
    "sample_block_geometry",
    "composite_mass_properties",
    "principal_inertia",
    "apply_block_geometry",
    "sample_colors",
]

#: Half sizes (metres) of the two cuboids: (length, width) ranges; ``gen`` is elongated.
BLOCK_SIZE_RANGES: dict[str, dict[str, tuple[float, float]]] = {
    "train": {"half_length": (0.018, 0.035), "half_width": (0.011, 0.018)},
    "gen": {"half_length": (0.040, 0.055), "half_width": (0.006, 0.009)},
}
BLOCK_HALF_HEIGHT = 0.015
BLOCK_DENSITY = 600.0  # kg / m^3 (wood)
SHAPES = ("L", "T", "I")


@dataclass(frozen=True)
class BlockGeometry:
    """Two cuboids in the body frame, centre of mass at the origin.

    Attributes:
        sizes: ``[2, 3]`` half sizes of the cuboids.
        positions: ``[2, 3]`` cuboid centres in the body frame (COM at the origin).
        shape: ``"L"``, ``"T"`` or ``"I"``.
    """

    sizes: np.ndarray
    positions: np.ndarray
    shape: str

    @property
    def footprint(self) -> tuple[np.ndarray, np.ndarray]:
        """Centre ``[2]`` and half extents ``[2]`` of the body-frame rectangle bounding both cuboids."""
        low = np.min(self.positions[:, :2] - self.sizes[:, :2], axis=0)
        high = np.max(self.positions[:, :2] + self.sizes[:, :2], axis=0)
        return (low + high) / 2.0, (high - low) / 2.0

    @property
    def planar_boxes(self) -> np.ndarray:
        """``[2, 4]`` body-frame footprints of the cuboids: (centre x, centre y, half x, half y)."""
        return np.concatenate([self.positions[:, :2], self.sizes[:, :2]], axis=1)


def sample_block_geometry(random: np.random.RandomState, geometry: str) -> BlockGeometry:
    """Draw a two-cuboid block from the ``"train"`` or ``"gen"`` size range."""
    if geometry not in BLOCK_SIZE_RANGES:
        raise ValueError(
            f"Unknown geometry {geometry!r}; choose one of {sorted(BLOCK_SIZE_RANGES)}."
        )
    ranges = BLOCK_SIZE_RANGES[geometry]
    len_a, len_b = random.uniform(*ranges["half_length"], size=2)
    wid_a, wid_b = random.uniform(*ranges["half_width"], size=2)
    shape = SHAPES[random.randint(len(SHAPES))]
    h = BLOCK_HALF_HEIGHT
    size_a = np.array([len_a, wid_a, h])
    if shape == "I":  # second bar continues the first along x
        size_b = np.array([len_b, wid_b, h])
        pos_b = np.array([len_a + len_b, 0.0, 0.0])
    else:  # second bar perpendicular, at the end (L) or the middle (T) of the first
        size_b = np.array([wid_b, len_b, h])
        x_b = len_a - wid_b if shape == "L" else 0.0
        pos_b = np.array([x_b, wid_a + len_b, 0.0])
    sizes = np.stack([size_a, size_b])
    positions = np.stack([np.zeros(3), pos_b])
    com, _, _ = composite_mass_properties(sizes, positions, BLOCK_DENSITY)
    return BlockGeometry(sizes=sizes, positions=positions - com, shape=shape)


def composite_mass_properties(
    sizes: np.ndarray, positions: np.ndarray, density: float
) -> tuple[np.ndarray, float, np.ndarray]:
    """Centre of mass, mass and inertia tensor (about the COM) of axis-aligned cuboids.

    Args:
        sizes: ``[G, 3]`` half sizes.
        positions: ``[G, 3]`` centres in the body frame.
        density: kg / m^3.

    Returns:
        ``com`` ``[3]``, ``mass`` and ``inertia`` ``[3, 3]`` about ``com`` in the body frame.
    """
    masses = density * 8.0 * np.prod(sizes, axis=1)
    mass = float(masses.sum())
    com = (masses[:, None] * positions).sum(axis=0) / mass
    inertia = np.zeros((3, 3))
    for m, half, pos in zip(masses, sizes, positions, strict=True):
        full_sq = (2.0 * half) ** 2
        box = (
            m
            / 12.0
            * np.diag([full_sq[1] + full_sq[2], full_sq[0] + full_sq[2], full_sq[0] + full_sq[1]])
        )
        d = pos - com
        inertia += box + m * (d @ d * np.eye(3) - np.outer(d, d))
    return com, mass, inertia


def principal_inertia(inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Diagonalise an inertia tensor: principal moments ``[3]`` and frame quaternion ``[4]`` (wxyz)."""
    moments, axes = np.linalg.eigh(inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1.0
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, axes.flatten())
    return moments, quat


def apply_block_geometry(
    model: mujoco.MjModel, body_id: int, geom_ids: tuple[int, int], block: BlockGeometry
) -> None:
    """Write ``block`` into the compiled model, keeping mass, COM, inertia and bounds consistent."""
    _, mass, inertia = composite_mass_properties(block.sizes, block.positions, BLOCK_DENSITY)
    moments, quat = principal_inertia(inertia)
    for gid, size, pos in zip(geom_ids, block.sizes, block.positions, strict=True):
        model.geom_size[gid] = size
        model.geom_pos[gid] = pos
        model.geom_rbound[gid] = float(np.linalg.norm(size))
        model.geom_aabb[gid] = np.concatenate([np.zeros(3), size])
    model.body_mass[body_id] = mass
    model.body_ipos[body_id] = 0.0
    model.body_iquat[body_id] = quat
    model.body_inertia[body_id] = moments


def sample_colors(random: np.random.RandomState, num: int) -> np.ndarray:
    """Draw ``num`` distinct saturated RGBA colours (hues evenly spread, random offset)."""
    hues = (
        random.uniform() + np.arange(num) / max(num, 1) + random.uniform(-0.05, 0.05, num)
    ) % 1.0
    hues = hues[random.permutation(num)]
    sat = random.uniform(0.65, 0.95, num)
    val = random.uniform(0.7, 0.95, num)
    k = (np.array([5.0, 3.0, 1.0])[None, :] + hues[:, None] * 6.0) % 6.0
    rgb = val[:, None] - val[:, None] * sat[:, None] * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)
    return np.concatenate([rgb, np.ones((num, 1))], axis=1)
