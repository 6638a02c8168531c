"""Next push for a real robot: ``python -m kinet_rl.plan --checkpoint kinet.pt --image now.png --goal goal.png``.

``--checkpoint pretrained:blocks_topview`` uses the model shipped with the package (no training).

With no other argument it plans as the model's results were produced: the planning objective
and planner budget stored in the checkpoint (chosen on validation episodes), and the workspace
and image size of the scene it was trained on (for a model trained on a robot's imported pushes,
the workspace its push folder stated, so pushes come out in the robot's metres, and its camera's
frames are cropped and resized as the import did). Images of another size are refused
(``--resize`` resizes them to the model's size and says so). Prints one JSON object per ``--image``: the push
start and end in metres (table frame, origin at the workspace centre, +x right and +y up in the
top camera image) and normalised to ``[-1, 1]``. The planner's warm start lives only within one
process: for closed-loop control call :class:`kinet_rl.models.PushPlanner` from Python (see
docs/planning.md), or pass several ``--image`` files to plan a push for each in turn, as if
executed one after another.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from kinet_rl.config_schema import ConfigError, require
from kinet_rl.models import PushPlanner
from kinet_rl.models.pretrained import resolve_checkpoint
from kinet_rl.planners import OBJECTIVES
from kinet_rl.planners.graph_mpc import check_planner_settings
from kinet_rl.rows import load_trained_model

logger = logging.getLogger(__name__)

#: The planner settings the command line can override, and the argument (``--<name>``) of each.
PLANNER_ARGUMENTS = {
    "planning_horizon": "horizon",
    "num_candidates": "candidates",
    "optim_steps": "iterations",
    "top_k": "top_k",
}


def read_image(path: Path, size: int | None = None) -> np.ndarray:
    """An RGB uint8 ``[H, W, 3]`` image; resized to ``size`` x ``size`` (and logged) if given
    and different."""
    if not path.is_file():
        raise FileNotFoundError(f"Image {path} does not exist.")
    image = Image.open(path).convert("RGB")
    if size is not None and image.size != (size, size):
        logger.info("Resizing %s from %dx%d to %dx%d px (--resize).", path, *image.size, size, size)
        image = image.resize((size, size), Image.Resampling.BILINEAR)
    return np.asarray(image)


def planner_overrides(args: argparse.Namespace) -> dict[str, int]:
    """The :class:`~kinet_rl.planners.GraphMPCPlanner` settings given on the command line."""
    return {
        name: getattr(args, dest)
        for name, dest in PLANNER_ARGUMENTS.items()
        if getattr(args, dest) is not None
    }


def check_args(args: argparse.Namespace) -> None:
    """Raises ``ConfigError`` (its key the argument's name) for arguments the planner refuses."""
    overrides = planner_overrides(args)
    for name, value in overrides.items():
        require(value >= 1, PLANNER_ARGUMENTS[name], value, "a positive integer")
    if "top_k" in overrides and "num_candidates" in overrides:
        candidates = overrides["num_candidates"]
        top_k = overrides["top_k"]
        require(top_k <= candidates, "top_k", top_k, f"at most num_candidates={candidates}")
    half_size = args.workspace_half_size
    require(half_size is None or half_size > 0, "workspace_half_size", half_size, "metres > 0")


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Command-line arguments, checked before any model is loaded."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--checkpoint",
        required=True,
        help="kinet.pt of a run, a model folder (save_pretrained), or pretrained:<name> for a "
        "shipped model (e.g. pretrained:blocks_topview)",
    )
    parser.add_argument("--image", type=Path, nargs="+", required=True, help="current image(s)")
    parser.add_argument("--goal", type=Path, required=True, help="goal image")
    parser.add_argument(
        "--resize",
        action="store_true",
        help="resize the images to the model's image size (default: refuse other sizes)",
    )
    parser.add_argument(
        "--workspace-half-size",
        type=float,
        default=None,
        help="metres; default from the checkpoint's scene (the workspace its imported dataset "
        "stated, else 0.20 blocks, 0.30 ycb)",
    )
    parser.add_argument(
        "--objective",
        choices=list(OBJECTIVES),
        default=None,
        help="planning objective (docs/planning.md); default: the checkpoint's",
    )
    parser.add_argument("--horizon", type=int, default=None, help="default: the checkpoint's")
    parser.add_argument("--candidates", type=int, default=None, help="default: the checkpoint's")
    parser.add_argument("--iterations", type=int, default=None, help="default: the checkpoint's")
    parser.add_argument("--top-k", type=int, default=None, help="default: the checkpoint's")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    try:
        check_args(args)
    except ConfigError as err:
        parser.error(f"argument --{err.key.replace('_', '-')}: {err.problem}")
    return args


def main(argv: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """Plans one push per ``--image`` and prints each as a JSON line."""
    args = parse_args(argv)
    model = load_trained_model(resolve_checkpoint(args.checkpoint))
    if model.scene is None and args.workspace_half_size is None:
        raise SystemExit(
            f"{args.checkpoint} does not say which scene it was trained on; pass "
            "--workspace-half-size (metres) and images of the model's size."
        )
    settings = {**model.planning.planner, **planner_overrides(args)}
    try:
        check_planner_settings(settings)
    except ConfigError as err:
        raise SystemExit(
            f"argument --{PLANNER_ARGUMENTS.get(err.key, err.key).replace('_', '-')}: "
            f"{err.problem} (with the checkpoint's planner settings {model.planning.planner})"
        ) from None
    planner = PushPlanner(
        model,
        objective=args.objective,
        planner=settings,
        workspace_half_size=args.workspace_half_size,
        seed=args.seed,
    )
    logger.info(
        "Planning with %s, objective %s, %s", type(model).__name__, planner.objective, settings
    )
    size = planner.image_size if args.resize else None
    goal = read_image(args.goal, size)
    pushes = []
    for path in args.image:
        try:
            push = planner.next_push(read_image(path, size), goal).as_dict()
        except ValueError as err:
            raise SystemExit(f"{path} and {args.goal}: {err}") from None
        pushes.append({"image": str(path), **push})
        sys.stdout.write(json.dumps(pushes[-1]) + "\n")
    return pushes


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO)
    main()
