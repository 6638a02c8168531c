"""Write a labelled contact sheet of the pushing scenes.

Usage: ``python -m kinet_rl.envs.preview [--out docs/preview.png] [--size 128] [--ycb-dir DIR]``.
Rows: task x camera; columns: object count, geometry and background variants. YCB rows need
the YCB assets (``--ycb-dir`` or ``$KINET_RL_YCB_DIR``) and are left out without them.
"""

from __future__ import annotations

import argparse
import logging
import os

import numpy as np
from PIL import Image, ImageDraw

from kinet_rl.atomic import atomic_save_with
from kinet_rl.envs.factory import make_dm_env
from kinet_rl.envs.ycb import YCB_DIR_ENV
from kinet_rl.keys import PIXELS

__all__ = ["render_contact_sheet", "main"]

logger = logging.getLogger(__name__)

#: (label, num_objects, geometry, background) of each column.
COLUMNS = (
    ("1 object", 1, "train", "fixed"),
    ("3 objects", 3, "train", "fixed"),
    ("5 objects", 5, "train", "fixed"),
    ("3, gen geometry", 3, "gen", "fixed"),
    ("3, random bg", 3, "train", "random"),
    ("5, gen + random bg", 5, "gen", "random"),
)
_LABEL_H = 14


def _scene(
    task: str, camera: str, size: int, column: tuple, seed: int, ycb_dir: str | None
) -> np.ndarray:
    _, num, geometry, background = column
    env = make_dm_env(
        task=task,
        num_objects=num,
        camera=camera,
        image_size=size,
        geometry=geometry,
        background=background,
        seed=seed,
        ycb_dir=ycb_dir,
    )
    return env.reset().observation[PIXELS]


def render_contact_sheet(size: int = 128, ycb_dir: str | None = None, seed: int = 0) -> Image.Image:
    """Render every (task, camera) x column scene into one labelled image."""
    tasks = ["blocks"] + (["ycb"] if ycb_dir or os.environ.get(YCB_DIR_ENV) else [])
    if len(tasks) == 1:
        logger.warning("No YCB assets (--ycb-dir or %s); the sheet shows blocks only.", YCB_DIR_ENV)
    rows = [(task, camera) for task in tasks for camera in ("top", "side")]
    label_w = 90
    sheet = Image.new("RGB", (label_w + len(COLUMNS) * size, _LABEL_H + len(rows) * size), "white")
    draw = ImageDraw.Draw(sheet)
    for c, column in enumerate(COLUMNS):
        draw.text((label_w + c * size + 2, 1), column[0], fill="black")
    for r, (task, camera) in enumerate(rows):
        top = _LABEL_H + r * size
        draw.text((2, top + size // 2 - 6), f"{task} / {camera}", fill="black")
        for c, column in enumerate(COLUMNS):
            pixels = _scene(task, camera, size, column, seed + c, ycb_dir)
            sheet.paste(Image.fromarray(pixels), (label_w + c * size, top))
    return sheet


def main(argv: list[str] | None = None) -> None:
    """Command-line entry point: write the contact sheet PNG atomically."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="docs/preview.png", help="output PNG path")
    parser.add_argument("--size", type=int, default=128, help="image size of each scene")
    parser.add_argument(
        "--ycb-dir", default=None, help=f"YCB asset folder (default ${YCB_DIR_ENV})"
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO)
    sheet = render_contact_sheet(args.size, args.ycb_dir, args.seed)
    out = atomic_save_with(args.out, lambda f: sheet.save(f, format="PNG"))
    logger.info("Wrote %s", out)


if __name__ == "__main__":
    main()
