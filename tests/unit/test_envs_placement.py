"""Unit tests of object placement, block geometry (sizes, mass properties) and colours."""

from __future__ import annotations

import numpy as np
import pytest

from kinet_rl.envs.blocks import (
    BLOCK_SIZE_RANGES,
    composite_mass_properties,
    principal_inertia,
    sample_block_geometry,
    sample_colors,
)
from kinet_rl.envs.placement import rectangle_inside, rectangles_overlap, sample_placements


def _point_in_rect(points, center, half, yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    local = (points - center) @ np.array([[c, -s], [s, c]])
    return np.all(np.abs(local) <= half, axis=-1)


def test_rectangles_overlap_known_cases():
    half = np.array([0.05, 0.01])
    assert rectangles_overlap(np.zeros(2), half, 0.0, np.array([0.09, 0.0]), half, 0.0)
    assert not rectangles_overlap(np.zeros(2), half, 0.0, np.array([0.0, 0.03]), half, 0.0)
    # Two thin bars in a plus sign overlap; two parallel diagonal bars side by side do not.
    assert rectangles_overlap(np.zeros(2), half, 0.0, np.zeros(2), half, np.pi / 2)
    assert not rectangles_overlap(
        np.zeros(2), half, np.pi / 4, np.array([0.06, -0.06]), half, np.pi / 4
    )
    assert rectangles_overlap(
        np.zeros(2), half, 0.0, np.array([0.0, 0.025]), half, 0.0, margin=0.003
    )


@pytest.mark.parametrize("num", [1, 3, 5])
def test_sample_placements_inside_and_without_overlap(num):
    random = np.random.RandomState(num)
    half = random.uniform(0.01, 0.05, size=(num, 2))
    offsets = random.uniform(-0.01, 0.01, size=(num, 2))
    bound = 0.2
    xy, yaw = sample_placements(random, half, bound, offsets=offsets, margin=0.005)
    assert xy.shape == (num, 2) and yaw.shape == (num,)
    assert np.all(np.abs(yaw) <= np.pi)
    rot = np.stack([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]).transpose(2, 0, 1)
    centers = xy + np.einsum("nij,nj->ni", rot, offsets)
    grid = np.stack(np.meshgrid(*[np.linspace(-bound, bound, 161)] * 2), -1).reshape(-1, 2)
    inside = [_point_in_rect(grid, centers[i], half[i], yaw[i]) for i in range(num)]
    for i in range(num):
        assert rectangle_inside(centers[i], half[i], yaw[i], bound)
        for j in range(i):  # independent check: no grid point covered twice
            assert not np.any(inside[i] & inside[j])


def test_sample_placements_is_seeded_and_fails_clearly():
    half = np.full((3, 2), 0.03)
    a = sample_placements(np.random.RandomState(0), half, 0.2)
    b = sample_placements(np.random.RandomState(0), half, 0.2)
    np.testing.assert_array_equal(a[0], b[0])
    with pytest.raises(ValueError, match="Could not place 5 objects"):
        sample_placements(np.random.RandomState(0), np.full((5, 2), 0.09), 0.2, restarts=2)


@pytest.mark.parametrize("geometry", ["train", "gen"])
def test_block_sizes_follow_their_range(geometry):
    random = np.random.RandomState(0)
    low_len, high_len = BLOCK_SIZE_RANGES[geometry]["half_length"]
    low_wid, high_wid = BLOCK_SIZE_RANGES[geometry]["half_width"]
    for _ in range(30):
        block = sample_block_geometry(random, geometry)
        lengths, widths = block.sizes[:, :2].max(axis=1), block.sizes[:, :2].min(axis=1)
        assert np.all((lengths >= low_len) & (lengths <= high_len))
        assert np.all((widths >= low_wid) & (widths <= high_wid))
        com, _, _ = composite_mass_properties(block.sizes, block.positions, 600.0)
        np.testing.assert_allclose(com, 0.0, atol=1e-12)  # COM at the body origin
    with pytest.raises(ValueError, match="Unknown geometry"):
        sample_block_geometry(random, "huge")


def test_gen_blocks_are_more_elongated_than_train():
    random = np.random.RandomState(1)

    def aspect(geometry):
        sizes = np.stack([sample_block_geometry(random, geometry).sizes for _ in range(20)])
        return np.mean(sizes[..., :2].max(-1) / sizes[..., :2].min(-1))

    assert aspect("gen") > 2.0 * aspect("train")


def test_composite_inertia_matches_a_single_box():
    # Two 1 x 1 x 1 halves side by side along x equal one 2 x 1 x 1 box.
    sizes = np.full((2, 3), 0.5)
    positions = np.array([[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]])
    com, mass, inertia = composite_mass_properties(sizes, positions, density=1.0)
    assert mass == pytest.approx(2.0)
    np.testing.assert_allclose(com, 0.0)
    expected = 2.0 / 12.0 * np.diag([1 + 1, 4 + 1, 4 + 1])
    np.testing.assert_allclose(inertia, expected, atol=1e-12)


def test_principal_inertia_reconstructs_tensor():
    random = np.random.RandomState(0)
    block = sample_block_geometry(random, "train")
    _, _, inertia = composite_mass_properties(block.sizes, block.positions, 600.0)
    moments, quat = principal_inertia(inertia)
    w, x, y, z = quat
    rot = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    np.testing.assert_allclose(rot @ np.diag(moments) @ rot.T, inertia, rtol=1e-9, atol=1e-15)
    assert np.all(moments > 0)


def test_colors_are_distinct_and_valid():
    colors = sample_colors(np.random.RandomState(0), 5)
    assert colors.shape == (5, 4)
    assert np.all((colors >= 0) & (colors <= 1))
    distances = np.linalg.norm(colors[:, None, :3] - colors[None, :, :3], axis=-1)
    assert distances[~np.eye(5, dtype=bool)].min() > 0.15
