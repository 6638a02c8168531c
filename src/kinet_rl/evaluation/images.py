"""Image summaries people look at: keypoint overlays, reconstruction grids, videos."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from PIL import Image, ImageDraw
from torch import Tensor

from kinet_rl.atomic import atomic_save_with

# Distinct colours for up to 12 keypoints (tab20-like), cycled beyond that.
KEYPOINT_COLOURS = [
    (230, 25, 75), (60, 180, 75), (255, 225, 25), (0, 130, 200), (245, 130, 48), (145, 30, 180),
    (70, 240, 240), (240, 50, 230), (210, 245, 60), (250, 190, 212), (0, 128, 128), (170, 110, 40),
]  # fmt: skip


def to_uint8_image(image: Tensor | np.ndarray) -> np.ndarray:
    """[H, W, 3] uint8 or float in [0, 1] -> uint8 numpy array."""
    array = image.detach().cpu().numpy() if isinstance(image, Tensor) else np.asarray(image)
    if array.dtype != np.uint8:
        array = (array.clip(0.0, 1.0) * 255.0).round().astype(np.uint8)
    return array


def draw_keypoints(image: Tensor | np.ndarray, kp_px: Tensor, scale: int = 4) -> np.ndarray:
    """Upscales an image and draws keypoints on it.

    Args:
        image: [H, W, 3] uint8 or float in [0, 1].
        kp_px: [K, 2] keypoints in pixel coordinates (x right, y down) of ``image``.
        scale: integer upscaling so that small images stay readable.
    """
    base = Image.fromarray(to_uint8_image(image))
    base = base.resize((base.width * scale, base.height * scale), Image.Resampling.NEAREST)
    draw = ImageDraw.Draw(base)
    radius = max(2, scale)
    for k, (x, y) in enumerate(kp_px.detach().cpu().tolist()):
        cx, cy = (x + 0.5) * scale, (y + 0.5) * scale
        colour = KEYPOINT_COLOURS[k % len(KEYPOINT_COLOURS)]
        draw.ellipse((cx - radius, cy - radius, cx + radius, cy + radius), outline=colour, width=2)
    return np.asarray(base)


def image_grid(rows: Sequence[Sequence[np.ndarray]], pad: int = 2) -> np.ndarray:
    """Tiles equally sized uint8 [H, W, 3] images into one image, row by row."""
    h, w = rows[0][0].shape[:2]
    ncols = max(len(r) for r in rows)
    grid = np.full((len(rows) * (h + pad) + pad, ncols * (w + pad) + pad, 3), 255, np.uint8)
    for i, row in enumerate(rows):
        for j, tile in enumerate(row):
            y, x = pad + i * (h + pad), pad + j * (w + pad)
            grid[y : y + h, x : x + w] = to_uint8_image(tile)
    return grid


def upscale(image: Tensor | np.ndarray, scale: int) -> np.ndarray:
    """Nearest-neighbour upscaling of an [H, W, 3] image to uint8."""
    return np.asarray(
        torch.as_tensor(to_uint8_image(image))
        .repeat_interleave(scale, 0)
        .repeat_interleave(scale, 1)
    )


def save_png(image: np.ndarray, path: str | os.PathLike) -> Path:
    """Writes a PNG atomically and returns its path."""
    return atomic_save_with(path, lambda f: Image.fromarray(image).save(f, format="PNG"))


def save_line_plot(fig, ax, path: Path, xlabel: str, ylabel: str, title: str) -> Path:
    """Labels, grid and legend of a matplotlib line plot; saves it atomically as PNG and closes it."""
    import matplotlib.pyplot as plt

    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    atomic_save_with(path, lambda f: fig.savefig(f, format="png", dpi=120))
    plt.close(fig)
    return path
