"""Procedural table-top textures, generated in memory (no binary assets in the repository).

Each texture is a small RGB PNG (bytes) built from a fixed seed, so scenes are identical across
machines. Per-episode variety comes from choosing one texture and a random RGBA tint.
"""

from __future__ import annotations

import functools
import io
from collections.abc import Callable

import numpy as np
from PIL import Image

__all__ = ["TABLE_TEXTURES", "table_texture_assets"]

_SIZE = 128


def _smooth_noise(rng: np.random.Generator, cells: int) -> np.ndarray:
    """Bilinearly upsampled uniform noise in [0, 1], shape ``[_SIZE, _SIZE]``."""
    grid = rng.uniform(size=(cells + 1, cells + 1))
    t = np.linspace(0.0, cells, _SIZE, endpoint=False)
    i, f = t.astype(int), t - t.astype(int)
    rows = grid[i] * (1 - f)[:, None] + grid[i + 1] * f[:, None]
    return rows[:, i] * (1 - f)[None, :] + rows[:, i + 1] * f[None, :]


def _wood(rng: np.random.Generator) -> np.ndarray:
    y, x = np.mgrid[0:_SIZE, 0:_SIZE] / _SIZE
    warp = 0.08 * _smooth_noise(rng, 4) + 0.02 * _smooth_noise(rng, 16)
    grain = 0.5 + 0.5 * np.sin(2 * np.pi * (14 * (y + warp) + 0.5 * x))
    planks = (np.floor(x * 4) % 2) * 0.06
    light = np.array([0.78, 0.58, 0.36])
    dark = np.array([0.55, 0.36, 0.19])
    img = dark + (light - dark) * (0.6 * grain + 0.4 * _smooth_noise(rng, 32))[..., None]
    return img * (1.0 - planks[..., None])


def _marble(rng: np.random.Generator) -> np.ndarray:
    y, x = np.mgrid[0:_SIZE, 0:_SIZE] / _SIZE
    turb = _smooth_noise(rng, 4) + 0.5 * _smooth_noise(rng, 8) + 0.25 * _smooth_noise(rng, 32)
    veins = np.abs(np.sin(2 * np.pi * (3 * x + 2 * y + 1.5 * turb)))
    return np.clip(0.55 + 0.4 * veins, 0, 1)[..., None] * np.array([0.95, 0.93, 0.9])


def _tiles(rng: np.random.Generator) -> np.ndarray:
    y, x = np.mgrid[0:_SIZE, 0:_SIZE] / _SIZE
    tile = ((np.floor(x * 8) + np.floor(y * 8)) % 2)[..., None]
    grout = ((x * 8 % 1 < 0.05) | (y * 8 % 1 < 0.05))[..., None]
    base = 0.75 + 0.15 * tile + 0.05 * _smooth_noise(rng, 32)[..., None]
    return np.where(grout, 0.35, base) * np.array([1.0, 0.97, 0.92])


def _fabric(rng: np.random.Generator) -> np.ndarray:
    y, x = np.mgrid[0:_SIZE, 0:_SIZE]
    weave = 0.5 + 0.25 * (np.sin(x * 1.3) + np.sin(y * 1.3))
    speckle = rng.uniform(size=(_SIZE, _SIZE))
    return (0.55 + 0.3 * weave + 0.15 * speckle)[..., None] * np.array([0.7, 0.8, 0.95])


def _plain(rng: np.random.Generator) -> np.ndarray:
    return np.full((_SIZE, _SIZE, 3), 0.92)


#: Name -> generator of an ``[H, W, 3]`` float image in [0, 1]. ``plain`` is the fixed blocks
#: background, ``wood`` the fixed YCB table.
TABLE_TEXTURES: dict[str, Callable[[np.random.Generator], np.ndarray]] = {
    "plain": _plain,
    "wood": _wood,
    "marble": _marble,
    "tiles": _tiles,
    "fabric": _fabric,
}


def _png_bytes(image: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray((np.clip(image, 0.0, 1.0) * 255).astype(np.uint8)).save(
        buffer, format="PNG", compress_level=1
    )
    return buffer.getvalue()


@functools.cache
def table_texture_assets() -> dict[str, bytes]:
    """PNG bytes of every table texture, keyed by the file name used in the MJCF (``<name>.png``)."""
    return {
        f"{name}.png": _png_bytes(make(np.random.default_rng(index)))
        for index, (name, make) in enumerate(TABLE_TEXTURES.items())
    }
