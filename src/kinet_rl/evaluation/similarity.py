"""Goal-image similarity that needs no object state: SSIM, the metric of runs on a real robot.

A rearrangement on a robot has no ground-truth object positions, only the camera image and the
goal image. The structural similarity index (SSIM) scores how alike the two images are, from 1
(identical) down: local means, variances and covariance under an 11 x 11 Gaussian window
(sigma 1.5), ``((2 mu_x mu_y + C1) (2 sigma_xy + C2)) / ((mu_x^2 + mu_y^2 + C1) (sigma_x^2 +
sigma_y^2 + C2))`` with ``C1 = (0.01 L)^2``, ``C2 = (0.03 L)^2`` and ``L`` the data range,
averaged over every window that fits inside the image and over the colour channels. Plain torch
(no weights, no extra dependency). The rearrangement evaluation reports it beside the
ground-truth goal distance on simulated episodes, so that one can see how well it tracks it.

Reference: Z. Wang, A. C. Bovik, H. R. Sheikh and E. P. Simoncelli, "Image quality assessment:
from error visibility to structural similarity", IEEE Trans. Image Processing 13(4), 2004.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

#: Side of the Gaussian window, its standard deviation (pixels) and the stabilising constants.
WINDOW, SIGMA, K1, K2 = 11, 1.5, 0.01, 0.03


def gaussian_window(size: int = WINDOW, sigma: float = SIGMA) -> Tensor:
    """The normalised 1-D Gaussian ``[size]`` whose outer product is SSIM's window."""
    offsets = torch.arange(size, dtype=torch.float64) - (size - 1) / 2
    weights = torch.exp(-(offsets**2) / (2 * sigma**2))
    return weights / weights.sum()


def ssim(
    image: Tensor | np.ndarray, reference: Tensor | np.ndarray, data_range: float = 255.0
) -> Tensor:
    """Mean SSIM of ``image`` against ``reference``.

    Args:
        image: ``[*B, H, W, C]`` images (uint8 camera frames, or floats in ``[0, data_range]``).
        reference: The same shape (e.g. the goal image); broadcast over ``*B`` if it has none.
        data_range: ``L``, the span of pixel values (255 for uint8).

    Returns:
        ``[*B]`` float64: 1 for identical images, lower as they differ.

    Raises:
        ValueError: Shapes that do not match, or images smaller than the window.
    """
    x = torch.as_tensor(image).to(torch.float64)
    y = torch.as_tensor(reference).to(torch.float64)
    if min(x.dim(), y.dim()) < 3 or x.shape[-3:] != y.shape[-3:]:
        raise ValueError(
            f"ssim needs images [*B, H, W, C] and a reference of the same size; got "
            f"{tuple(x.shape)} and {tuple(y.shape)}."
        )
    height, width, channels = x.shape[-3:]
    if min(height, width) < WINDOW:
        raise ValueError(
            f"ssim needs images of at least {WINDOW} x {WINDOW} pixels (its window); got "
            f"{height} x {width}."
        )
    x, y = torch.broadcast_tensors(x, y)
    batch = x.shape[:-3]
    x = x.reshape(-1, height, width, channels).permute(0, 3, 1, 2)  # [B, C, H, W]
    y = y.reshape(-1, height, width, channels).permute(0, 3, 1, 2)
    c1, c2 = (K1 * data_range) ** 2, (K2 * data_range) ** 2
    mu_x, mu_y = _blur(x), _blur(y)
    var_x = _blur(x * x) - mu_x**2
    var_y = _blur(y * y) - mu_y**2
    cov = _blur(x * y) - mu_x * mu_y
    index = ((2 * mu_x * mu_y + c1) * (2 * cov + c2)) / (
        (mu_x**2 + mu_y**2 + c1) * (var_x + var_y + c2)
    )  # [B, C, H - WINDOW + 1, W - WINDOW + 1]
    return index.mean(dim=(1, 2, 3)).reshape(batch)


def _blur(images: Tensor) -> Tensor:
    """Gaussian-weighted local means of ``[B, C, H, W]`` over every full window (separable)."""
    channels = images.shape[1]
    weights = gaussian_window().to(images)
    rows = weights.view(1, 1, WINDOW, 1).expand(channels, 1, WINDOW, 1)
    columns = weights.view(1, 1, 1, WINDOW).expand(channels, 1, 1, WINDOW)
    return F.conv2d(F.conv2d(images, rows, groups=channels), columns, groups=channels)
