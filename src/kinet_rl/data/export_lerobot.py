"""Export a dataset as LeRobot v3.0: ``python -m kinet_rl.data.export_lerobot <dataset> <out>``.

The camera as PNG images in the Parquet files (bit-exact), or with ``--video`` as AV1 MP4 videos
(lossy, smaller; needs PyAV); ``action`` the push in metres (table frame); see
:mod:`kinet_rl.data.lerobot_writer`, :mod:`kinet_rl.data.lerobot` (the layout) and docs/data.md
("LeRobot v3"). Exit status: 0 done, 2 bad input.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from kinet_rl.data.lerobot import DEFAULT_CAMERA, DEFAULT_FPS
from kinet_rl.data.lerobot_writer import export_lerobot
from kinet_rl.data.storage import DatasetError


def main(argv: Sequence[str] | None = None) -> Path:
    """Exports the dataset; returns the LeRobot folder."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", type=Path, help="a complete kinet_rl dataset folder")
    parser.add_argument("out", type=Path, help="the new LeRobot folder (absent or empty)")
    parser.add_argument("--camera", default=DEFAULT_CAMERA, help="camera feature key")
    parser.add_argument("--fps", type=int, default=DEFAULT_FPS, help="stated frame rate")
    parser.add_argument(
        "--no-object-state", action="store_true", help="leave out object positions and yaws"
    )
    parser.add_argument(
        "--video", action="store_true", help="store the camera as AV1 MP4 videos (lossy)"
    )
    args = parser.parse_args(argv)
    try:
        out = export_lerobot(
            args.dataset,
            args.out,
            camera=args.camera,
            include_object_state=not args.no_object_state,
            fps=args.fps,
            video=args.video,
        )
    except DatasetError as err:
        sys.stderr.write(f"error: {type(err).__name__}: {err}\n")
        raise SystemExit(2) from None
    print(f"Done: {out}", flush=True)
    return out


if __name__ == "__main__":
    main()
