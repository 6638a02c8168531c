"""SSIM, the goal-image similarity without object state, against closed forms and a reference."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from kinet_rl.evaluation.similarity import K1, K2, SIGMA, WINDOW, ssim


def reference_ssim(x: np.ndarray, y: np.ndarray, data_range: float = 255.0) -> float:
    """SSIM written out window by window: Gaussian-weighted statistics of every full window."""
    offsets = np.arange(WINDOW) - (WINDOW - 1) / 2
    g = np.exp(-(offsets**2) / (2 * SIGMA**2))
    weights = np.outer(g, g) / np.outer(g, g).sum()
    c1, c2 = (K1 * data_range) ** 2, (K2 * data_range) ** 2
    x, y = x.astype(np.float64), y.astype(np.float64)
    values = []
    for channel in range(x.shape[-1]):
        for i in range(x.shape[0] - WINDOW + 1):
            for j in range(x.shape[1] - WINDOW + 1):
                a = x[i : i + WINDOW, j : j + WINDOW, channel]
                b = y[i : i + WINDOW, j : j + WINDOW, channel]
                mu_a, mu_b = (weights * a).sum(), (weights * b).sum()
                var_a = (weights * (a - mu_a) ** 2).sum()
                var_b = (weights * (b - mu_b) ** 2).sum()
                cov = (weights * (a - mu_a) * (b - mu_b)).sum()
                values.append(
                    (2 * mu_a * mu_b + c1)
                    * (2 * cov + c2)
                    / ((mu_a**2 + mu_b**2 + c1) * (var_a + var_b + c2))
                )
    return float(np.mean(values))


def test_an_image_is_fully_similar_to_itself(random_images) -> None:
    image = random_images((2,), 0, size=32)
    assert ssim(image, image).tolist() == pytest.approx([1.0, 1.0], abs=1e-12)


def test_similarity_falls_as_noise_grows() -> None:
    rows, columns = torch.meshgrid(torch.arange(32.0), torch.arange(32.0), indexing="ij")
    pattern = 128 + 60 * torch.sin(rows / 5) * torch.cos(columns / 7)  # a smooth scene
    image = pattern[..., None].expand(32, 32, 3).double()
    noise = torch.randn(image.shape, generator=torch.Generator().manual_seed(2))
    scores = [
        ssim((image + sigma * noise).clamp(0, 255), image).item()
        for sigma in (0, 5, 10, 20, 40, 80)
    ]
    assert scores[0] == pytest.approx(1.0)
    assert all(a > b for a, b in zip(scores, scores[1:], strict=False)), scores
    assert scores[-1] < 0.2


def test_flat_images_give_the_closed_form_of_their_means() -> None:
    # No variance: SSIM = (2 a b + C1) / (a^2 + b^2 + C1) in every window.
    a, b = np.full((16, 16, 3), 100, np.uint8), np.full((16, 16, 3), 150, np.uint8)
    c1 = (K1 * 255) ** 2
    expected = (2 * 100 * 150 + c1) / (100**2 + 150**2 + c1)
    assert ssim(a, b).item() == pytest.approx(expected, rel=1e-12)
    assert expected == pytest.approx(0.92309, abs=1e-5)


def test_matches_the_window_by_window_reference() -> None:
    rng = np.random.default_rng(0)
    x = rng.integers(0, 256, (14, 17, 3), dtype=np.uint8)
    y = np.clip(x + rng.normal(0, 30, x.shape), 0, 255).astype(np.uint8)
    assert ssim(x, y).item() == pytest.approx(reference_ssim(x, y), rel=1e-10)
    assert ssim(x, y).item() == pytest.approx(ssim(y, x).item(), rel=1e-12)  # symmetric


def test_a_batch_is_scored_against_one_reference(random_images) -> None:
    images, goal = random_images((3,), 3), random_images((), 4)
    scores = ssim(images, goal)
    assert scores.shape == (3,) and scores.dtype == torch.float64
    assert scores[1].item() == pytest.approx(ssim(images[1], goal).item(), rel=1e-12)


def test_bad_shapes_are_refused_with_the_shapes_named() -> None:
    with pytest.raises(ValueError, match=r"same size; got \(16, 16, 3\) and \(16, 12, 3\)"):
        ssim(np.zeros((16, 16, 3)), np.zeros((16, 12, 3)))
    with pytest.raises(ValueError, match="at least 11 x 11 pixels"):
        ssim(np.zeros((8, 8, 3)), np.zeros((8, 8, 3)))
