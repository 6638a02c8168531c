"""Next push for a real robot: ``python -m kinet_rl.plan --checkpoint kinet.pt --image now.png --goal goal.png``.

``--checkpoint pretrained:blocks_topview`` uses the model shipped with the package (no training).

Prints one JSON object: the push start and end in metres (table frame, origin at the workspace
centre, +x right and +y up in the top camera image) and normalised to ``[-1, 1]``. Images must
come from the camera and resolution the model was trained on. The planner's warm start lives
only within one process: for closed-loop control call :class:`kinet_rl.models.PushPlanner`
from Python (see docs/planning.md), or pass several ``--image`` files to plan a push for each in
turn, as if executed one after another.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image

from kinet_rl.config_schema import ConfigError, require
from kinet_rl.envs.settings import check_image_size
from kinet_rl.envs.workspace import WORKSPACES
from kinet_rl.models import REWARDS, KINetWorldModel, PushPlanner
from kinet_rl.models.checkpointing import checkpoint_scene
from kinet_rl.models.pretrained import resolve_checkpoint
from kinet_rl.planners.graph_mpc import check_planner_settings

logger = logging.getLogger(__name__)

#: The planner settings of :class:`PushPlanner` and the argument (``--<name>``) that sets each.
PLANNER_ARGUMENTS = {
    "planning_horizon": "horizon",
    "num_candidates": "candidates",
    "optim_steps": "iterations",
    "top_k": "top_k",
}


def read_image(path: Path, size: int | None = None) -> np.ndarray:
    """An RGB uint8 ``[H, W, 3]`` image, resized to ``size`` x ``size`` if given."""
    if not path.is_file():
        raise FileNotFoundError(f"Image {path} does not exist.")
    image = Image.open(path).convert("RGB")
    if size is not None and image.size != (size, size):
        image = image.resize((size, size), Image.Resampling.BILINEAR)
    return np.asarray(image)


def planner_settings(args: argparse.Namespace) -> dict[str, int]:
    """The :class:`~kinet_rl.planners.GraphMPCPlanner` settings of the command line."""
    return {name: getattr(args, dest) for name, dest in PLANNER_ARGUMENTS.items()}


def check_args(args: argparse.Namespace) -> None:
    """Raises ``ConfigError`` (its key the argument's name) for arguments the planner refuses."""
    try:
        check_planner_settings(planner_settings(args))
    except ConfigError as err:
        raise ConfigError(PLANNER_ARGUMENTS.get(err.key, err.key), err.problem) from None
    if args.image_size is not None:
        check_image_size(args.image_size)
    half_size = args.workspace_half_size
    require(half_size is None or half_size > 0, "workspace_half_size", half_size, "metres > 0")


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Command-line arguments, checked before any model is loaded."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--checkpoint",
        required=True,
        help="kinet.pt of a run, or pretrained:<name> for a shipped model (e.g. "
        "pretrained:blocks_topview)",
    )
    parser.add_argument("--image", type=Path, nargs="+", required=True, help="current image(s)")
    parser.add_argument("--goal", type=Path, required=True, help="goal image")
    parser.add_argument(
        "--workspace-half-size",
        type=float,
        default=None,
        help="metres; default from the checkpoint's env task (0.20 blocks, 0.30 ycb)",
    )
    parser.add_argument(
        "--image-size",
        type=int,
        default=None,
        help="resize images to this square size (default: the checkpoint's env)",
    )
    parser.add_argument(
        "--reward",
        choices=sorted(REWARDS),
        default="graph_distance",
        help="planning objective (docs/planning.md); graph = the paper's S",
    )
    parser.add_argument("--horizon", type=int, default=1)
    parser.add_argument("--candidates", type=int, default=256)
    parser.add_argument("--iterations", type=int, default=5)
    parser.add_argument("--top-k", type=int, default=32)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    try:
        check_args(args)
    except ConfigError as err:
        parser.error(f"argument --{err.key.replace('_', '-')}: {err.problem}")
    return args


def main(argv: Sequence[str] | None = None) -> list[dict]:
    """Plans one push per ``--image`` and prints each as a JSON line."""
    args = parse_args(argv)
    checkpoint = resolve_checkpoint(args.checkpoint)
    model = KINetWorldModel.from_checkpoint(checkpoint)
    scene = checkpoint_scene(checkpoint)
    task = "blocks" if scene is None else scene.task
    half_size = args.workspace_half_size or WORKSPACES[task].half_size
    size = args.image_size or (None if scene is None else scene.image_size)
    planner = PushPlanner(
        model,
        half_size,
        reward=REWARDS[args.reward](),
        seed=args.seed,
        **planner_settings(args),
    )
    goal = read_image(args.goal, size)
    pushes = []
    for path in args.image:
        push = planner.next_push(read_image(path, size), goal).as_dict()
        pushes.append({"image": str(path), **push})
        sys.stdout.write(json.dumps(pushes[-1]) + "\n")
    return pushes


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO)
    main()
