"""Collision-free placement of objects in the workspace (pure numpy, no MuJoCo).

Objects are approximated by their footprint: a rectangle in the body frame, centred on the
body origin, rotated by the object's yaw. Two objects overlap when their rotated rectangles
(grown by a margin) intersect, which is tested with the separating-axis theorem.
"""

from __future__ import annotations

import numpy as np

__all__ = ["rectangles_overlap", "rectangle_inside", "sample_placements"]


def _corners(center: np.ndarray, half_extents: np.ndarray, yaw: float) -> np.ndarray:
    """Corners ``[4, 2]`` of a rectangle with ``half_extents`` rotated by ``yaw``."""
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, -s], [s, c]])
    signs = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]], dtype=float)
    return center + (signs * half_extents) @ rot.T


def rectangles_overlap(
    center_a: np.ndarray,
    half_a: np.ndarray,
    yaw_a: float,
    center_b: np.ndarray,
    half_b: np.ndarray,
    yaw_b: float,
    margin: float = 0.0,
) -> bool:
    """Whether two rotated rectangles, each grown by ``margin`` on every side, intersect."""
    corners_a = _corners(center_a, np.asarray(half_a) + margin, yaw_a)
    corners_b = _corners(center_b, np.asarray(half_b) + margin, yaw_b)
    for yaw in (yaw_a, yaw_b):
        for axis in (np.array([np.cos(yaw), np.sin(yaw)]), np.array([-np.sin(yaw), np.cos(yaw)])):
            proj_a, proj_b = corners_a @ axis, corners_b @ axis
            if proj_a.max() < proj_b.min() or proj_b.max() < proj_a.min():
                return False
    return True


def rectangle_inside(
    center: np.ndarray, half_extents: np.ndarray, yaw: float, bound: float
) -> bool:
    """Whether a rotated rectangle lies inside the square ``[-bound, bound]^2``."""
    return bool(np.all(np.abs(_corners(center, half_extents, yaw)) <= bound))


def sample_placements(
    random: np.random.RandomState,
    half_extents: np.ndarray,
    bound: float,
    offsets: np.ndarray | None = None,
    margin: float = 0.01,
    tries_per_object: int = 200,
    restarts: int = 20,
) -> tuple[np.ndarray, np.ndarray]:
    """Sample non-overlapping poses for objects inside the square ``[-bound, bound]^2``.

    Objects are placed one after another by rejection sampling (uniform centre and yaw);
    if one cannot be placed, the whole scene is sampled again.

    Args:
        random: source of randomness (the dm_control task's ``self.random``).
        half_extents: ``[N, 2]`` footprint half extents of each object, metres.
        bound: half side of the square that must contain every footprint, metres.
        offsets: ``[N, 2]`` footprint centres in the body frame (default: the body origin).
        margin: minimal gap kept between footprints, metres.
        tries_per_object: rejection-sampling attempts per object before a restart.
        restarts: number of whole-scene attempts before giving up.

    Returns:
        ``xy`` ``[N, 2]`` centres and ``yaw`` ``[N]`` in ``[-pi, pi)``.

    Raises:
        ValueError: the objects cannot be placed; use fewer or smaller objects or a larger
            workspace.
    """
    half_extents = np.asarray(half_extents, dtype=float).reshape(-1, 2)
    num = len(half_extents)
    offsets = (
        np.zeros((num, 2)) if offsets is None else np.asarray(offsets, dtype=float).reshape(num, 2)
    )
    for _ in range(restarts):
        xy, yaw, centers = np.zeros((num, 2)), np.zeros(num), np.zeros((num, 2))
        placed = 0
        for i in range(num):
            lim = max(bound - float(half_extents[i].min()), 0.0)
            for _ in range(tries_per_object):
                yaw_i = random.uniform(-np.pi, np.pi)
                xy_i = random.uniform(-lim, lim, size=2)
                c, s = np.cos(yaw_i), np.sin(yaw_i)
                center_i = xy_i + np.array([[c, -s], [s, c]]) @ offsets[i]
                if not rectangle_inside(center_i, half_extents[i], yaw_i, bound):
                    continue
                if any(
                    rectangles_overlap(
                        center_i,
                        half_extents[i],
                        yaw_i,
                        centers[j],
                        half_extents[j],
                        yaw[j],
                        margin,
                    )
                    for j in range(i)
                ):
                    continue
                xy[i], yaw[i], centers[i] = xy_i, yaw_i, center_i
                placed += 1
                break
            else:
                break
        if placed == num:
            return xy, yaw
    raise ValueError(
        f"Could not place {num} objects (footprint half extents {half_extents.tolist()}) without "
        f"overlap inside a workspace of half size {bound} m; use fewer or smaller objects or a "
        "larger workspace."
    )
