"""Contract tests for the keypoint detector, transport and reconstructor."""

from __future__ import annotations

import pytest
import torch

from kinet_rl.models.keypoints import (
    KeypointDetector,
    KeypointReconstructor,
    gaussian_maps,
    shift_transport,
    spatial_soft_argmax,
    transport,
)


@pytest.fixture
def detector() -> KeypointDetector:
    torch.manual_seed(0)
    return KeypointDetector(num_keypoints=3, feat_dim=5, channels=8)


def test_detector_shapes_dtypes_and_range(detector):
    pixels = torch.randint(0, 256, (2, 4, 16, 16, 3), dtype=torch.uint8)
    pos, feat = detector(pixels)
    assert pos.shape == (2, 4, 3, 2) and pos.dtype == torch.float32
    assert feat.shape == (2, 4, 3, 5) and feat.dtype == torch.float32
    assert pos.abs().max() <= 1.0


def test_detector_uint8_and_float_agree_and_input_is_untouched(detector):
    pixels = torch.randint(0, 256, (2, 16, 16, 3), dtype=torch.uint8)
    original = pixels.clone()
    pos_u8, feat_u8 = detector(pixels)
    pos_f, feat_f = detector(pixels.float() / 255)
    torch.testing.assert_close(pos_u8, pos_f)
    torch.testing.assert_close(feat_u8, feat_f)
    assert torch.equal(pixels, original)


@pytest.mark.parametrize(
    ("shape", "dtype", "match"),
    [
        ((2, 3, 16, 16), torch.uint8, "channels last"),
        ((2, 18, 18, 3), torch.uint8, "divisible by 4"),
        ((2, 16, 16, 3), torch.int32, "uint8 or float"),
    ],
)
def test_detector_rejects_bad_images(detector, shape, dtype, match):
    with pytest.raises((ValueError, TypeError), match=match):
        detector(torch.zeros(shape, dtype=dtype))


def test_half_resolution_heatmaps_pool_features_over_the_quarter_resolution_map():
    torch.manual_seed(0)
    detector = KeypointDetector(num_keypoints=3, feat_dim=5, channels=8, heatmap_stride=2)
    enc = detector.encode(torch.rand(2, 16, 16, 3))
    logits = detector.heatmap_head(enc.coarse, enc.fine)
    assert logits.shape == (2, 3, 8, 8)  # 1/2 of the image, where the coarse map is 4x4
    pos, heat = spatial_soft_argmax(logits)
    torch.testing.assert_close(enc.pos, pos)
    cell_share = heat.reshape(2, 3, 4, 2, 4, 2).sum(dim=(3, 5))  # each 2x2 block of a coarse cell
    pooled = torch.einsum("nkhw,nchw->nkc", cell_share, enc.coarse)
    torch.testing.assert_close(enc.feat, detector.feat_head(pooled))


def test_a_heatmap_stride_other_than_4_or_2_is_named():
    with pytest.raises(ValueError, match=r"heatmap_stride=8; choose one of \(4, 2\)"):
        KeypointDetector(heatmap_stride=8)


def test_soft_argmax_convention_x_right_y_down():
    logits = torch.full((1, 1, 8, 8), -50.0)
    logits[0, 0, 1, 6] = 50.0  # row 1 (top), column 6 (right)
    pos, heat = spatial_soft_argmax(logits)
    torch.testing.assert_close(pos[0, 0], torch.tensor([(6 * 2 + 1) / 8 - 1, (1 * 2 + 1) / 8 - 1]))
    torch.testing.assert_close(heat.sum(dim=(-2, -1)), torch.ones(1, 1))


def test_gaussian_maps_peak_at_keypoint():
    maps = gaussian_maps(torch.tensor([[[0.375, -0.625]]]), 8, 8, std=0.1)
    row, col = divmod(int(maps[0, 0].argmax()), 8)
    assert (row, col) == (1, 5)


def pixel_centre(row: int, col: int, size: int) -> list[float]:
    """``(x, y)`` in ``[-1, 1]`` of a pixel centre (align_corners=False)."""
    return [(2 * col + 1) / size - 1, (2 * row + 1) / size - 1]


def test_shift_transport_moves_source_features_to_target():
    # Keypoints on pixel centres: the blob is exactly 1 there and the shift is whole pixels,
    # so the feature must vanish at the source and reappear, intact, at the target.
    source = torch.zeros(1, 2, 16, 16)
    source[0, :, 4, 4] = torch.tensor([1.0, -2.0])
    pos_src = torch.tensor([[pixel_centre(4, 4, 16)]])
    pos_tgt = torch.tensor([[pixel_centre(10, 12, 16)]])
    moved = shift_transport(source, pos_src, pos_tgt, std=0.1)
    expected = torch.zeros_like(source)
    expected[0, :, 10, 12] = torch.tensor([1.0, -2.0])
    torch.testing.assert_close(moved, expected, atol=1e-5, rtol=0)


def test_transport_pastes_target_features_and_keeps_the_rest():
    gen = torch.Generator().manual_seed(0)
    source, target = torch.rand(2, 1, 3, 16, 16, generator=gen)
    pos_src = torch.tensor([[pixel_centre(2, 2, 16)]])
    pos_tgt = torch.tensor([[pixel_centre(3, 4, 16)]])
    for out in (
        transport(source, target, pos_src, pos_tgt, std=0.05),
        shift_transport(source, pos_src, pos_tgt, std=0.05),
    ):
        far = (slice(None), slice(None), slice(10, 16), slice(10, 16))  # > 0.75 away: blobs ~0
        torch.testing.assert_close(out[far], source[far])
    rebuilt = transport(source, target, pos_src, pos_tgt, std=0.05)
    torch.testing.assert_close(rebuilt[..., 3, 4], target[..., 3, 4])  # target blob peak
    assert rebuilt[..., 2, 2].abs().max() < 0.05  # source blob suppressed (target blob ~0 there)


def test_reconstructor_rebuilds_and_renders_full_size_images(detector):
    reconstructor = KeypointReconstructor(channels=8, std=0.1)
    enc = detector.encode(torch.rand(3, 16, 16, 3))
    source, target = enc.split(2)[0], detector.encode(torch.rand(2, 16, 16, 3))
    rebuilt = reconstructor(source, target)
    rendered = reconstructor.render(enc, enc.pos.flip(0))
    assert rebuilt.shape == (2, 16, 16, 3) and rendered.shape == (3, 16, 16, 3)
    assert torch.isfinite(rebuilt).all() and torch.isfinite(rendered).all()
