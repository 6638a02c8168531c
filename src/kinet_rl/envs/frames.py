"""A camera's frames to a model's square images: the crop and resize an import applies, which
planning applies again to the robot's live frames."""

from __future__ import annotations

import numpy as np
from PIL import Image


def resize_filter(box_size: int, image_size: int) -> Image.Resampling:
    """Box (area average) when shrinking a ``box_size`` square to ``image_size``, bicubic when
    enlarging it."""
    return Image.Resampling.BOX if box_size >= image_size else Image.Resampling.BICUBIC


def square_frame(image: Image.Image, box: tuple[int, int, int], image_size: int) -> Image.Image:
    """The square ``box`` = ``(left, top, size)`` of ``image``, resized to ``image_size`` px."""
    left, top, size = box
    square = image.crop((left, top, left + size, top + size))
    if square.size == (image_size, image_size):
        return square
    return square.resize((image_size, image_size), resize_filter(size, image_size))


def square_array(frame: np.ndarray, box: tuple[int, int, int], image_size: int) -> np.ndarray:
    """:func:`square_frame` of an RGB uint8 ``[H, W, 3]`` array."""
    return np.asarray(square_frame(Image.fromarray(frame), box, image_size))
