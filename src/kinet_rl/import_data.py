"""Import a robot's pushes: ``python -m kinet_rl.import_data <push folder> --name <name>``.

Turns a plain push folder (per episode PNG frames and one pushes file; docs/data.md, "Your own
robot's pushes") into a kinet_rl dataset of pixels and pushes without object state, which
``python -m kinet_rl.train data.root=<root> data.name=<name> env.image_size=<size>`` trains
KINet (or V-CDN, Forw, ForwInv) on. Checks the whole folder first and stops with a named error
for bad input (nothing written); prints what it will do (crop, resize, episode windows,
splits), then writes with a progress bar. Rerun the same command to resume an interrupted
import. A LeRobot v3.0 dataset (a folder with ``meta/info.json``; the camera as images or as
video) is imported through the same path (:mod:`kinet_rl.data.lerobot`; ``--camera-key``,
``--action-key``, ``--workspace-half-size``). Exit status: 0 done, 2 bad input or arguments.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

from kinet_rl.config_schema import ConfigError
from kinet_rl.data.importing import (
    CENTRE_CROP,
    ImportPlan,
    ImportSettings,
    import_push_folder,
    plan_import,
)
from kinet_rl.data.lerobot import is_lerobot_folder
from kinet_rl.data.push_folder import UNITS, PushFolder, PushFolderError
from kinet_rl.data.storage import DatasetError

logger = logging.getLogger(__name__)

#: The training defaults (``conf/config.yaml``) an imported dataset's episodes must fit.
DEFAULT_HORIZONS = (1, 5, 10)
DEFAULT_TRAINER_HORIZON = 3


def parse_crop(text: str) -> str | tuple[int, int, int]:
    """``center`` or ``LEFT,TOP,SIZE`` (pixels)."""
    if text == CENTRE_CROP:
        return text
    try:
        left, top, size = (int(value) for value in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: give {CENTRE_CROP} or LEFT,TOP,SIZE in pixels (e.g. 280,0,720)"
        ) from None
    return (left, top, size)


def parse_splits(text: str) -> dict[str, float]:
    """``train=0.8,val=0.1,test=0.1``."""
    try:
        return {name: float(value) for name, value in (p.split("=") for p in text.split(","))}
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: give NAME=FRACTION pairs, e.g. train=0.8,val=0.1,test=0.1"
        ) from None


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Command-line arguments."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "source", type=Path, help="the push folder (meta.json, episode_*/) or a LeRobot v3.0 one"
    )
    parser.add_argument("--root", type=Path, default=Path("data"), help="datasets folder")
    parser.add_argument("--name", default=None, help="dataset name (default: the folder's name)")
    parser.add_argument(
        "--image-size", type=int, default=64, help="side of the square training images, px"
    )
    parser.add_argument(
        "--crop",
        type=parse_crop,
        default=None,
        help=f"{CENTRE_CROP} (largest centred square) or LEFT,TOP,SIZE; needed for non-square "
        "frames",
    )
    parser.add_argument(
        "--episode-length",
        type=int,
        default=None,
        help="pushes per stored episode (default: the shortest episode's); longer episodes are "
        "cut into windows of this many pushes",
    )
    parser.add_argument(
        "--splits",
        type=parse_splits,
        default=None,
        help="fractions of the episodes per split (default train=0.8,val=0.1,test=0.1)",
    )
    parser.add_argument("--chunk-episodes", type=int, default=16, help="episodes per commit")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    lerobot = parser.add_argument_group("LeRobot v3.0 datasets (a folder with meta/info.json)")
    lerobot.add_argument(
        "--camera-key", default=None, help="image feature (observation.images.top)"
    )
    lerobot.add_argument("--action-key", default=None, help="4-d push feature (action)")
    lerobot.add_argument(
        "--action-units",
        choices=UNITS,
        default=None,
        help="the action's units: metres (table frame) or normalised (metres / workspace half "
        "size); default: info.json's kinet_rl.action_units, else metres",
    )
    lerobot.add_argument(
        "--workspace-half-size",
        type=float,
        default=None,
        help="metres; needed when info.json has no kinet_rl.workspace_half_size",
    )
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> Path:
    """Imports the folder; returns the dataset's path."""
    args = parse_args(argv)
    name = args.name or args.source.resolve().name
    try:
        settings = ImportSettings(
            image_size=args.image_size,
            crop=args.crop,
            episode_length=args.episode_length,
            chunk_episodes=args.chunk_episodes,
            **({} if args.splits is None else {"splits": args.splits}),
        )
        plan = plan_import(source_folder(args), settings)
    except (PushFolderError, ConfigError, ImportError) as err:  # ImportError: an extra missing
        sys.stderr.write(f"error: {type(err).__name__}: {err}\n")
        raise SystemExit(2) from None
    path = args.root / name
    print(plan.describe(path), flush=True)
    try:
        import_push_folder(plan, args.root, name, progress=not args.no_progress)
    except DatasetError as err:
        sys.stderr.write(f"error: {type(err).__name__}: {err}\n")
        raise SystemExit(2) from None
    print(f"Done: {path}. Train on it with: {train_command(args.root, name, plan)}", flush=True)
    return path


def source_folder(args: argparse.Namespace) -> Path | PushFolder:
    """The push folder's path, or a LeRobot dataset's episodes as a checked push folder."""
    if not is_lerobot_folder(args.source):
        return args.source
    from kinet_rl.data.lerobot import DEFAULT_ACTION, DEFAULT_CAMERA, read_lerobot

    return read_lerobot(
        args.source,
        camera_key=args.camera_key or DEFAULT_CAMERA,
        action_key=args.action_key or DEFAULT_ACTION,
        workspace_half_size=args.workspace_half_size,
        action_units=args.action_units,
    ).as_push_folder()


def train_command(root: Path, name: str, plan: ImportPlan) -> str:
    """The training command of an imported dataset: its image size, and horizons that fit its
    episodes where the defaults (``report.horizons=[1,5,10]``, ``trainer.horizon=3``) do not."""
    overrides = [f"data.root={root}", f"data.name={name}", f"env.image_size={plan.image_size}"]
    length = plan.episode_length
    if length < max(DEFAULT_HORIZONS):
        horizons = sorted({h for h in DEFAULT_HORIZONS if h <= length} | {length})
        overrides.append(f"report.horizons=[{','.join(str(h) for h in horizons)}]")
    if length < DEFAULT_TRAINER_HORIZON:
        overrides.append(f"trainer.horizon={length}")
    return " ".join(["python -m kinet_rl.train", *overrides])


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO)
    main()
