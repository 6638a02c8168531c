"""Ship a trained KINet as a model folder with its card:
``python docs/scripts/ship_model.py --run runs/<exp>_cpu --name <name> --out <folder> ...``.

Measures what the card states, on the run's own dataset and on fresh episodes: the keypoint
accuracy of the run's report (``results.json``), Table I's forward errors (1,024 test sequences,
seed 0, with no motion and the detector floor; ``forward_error.py``), and the ``check`` that
``tests/integration/test_pretrained.py`` repeats (keypoint accuracy on episodes collected afresh,
``kinet_rl.pipeline.CHECK_PROTOCOL``). Then writes ``--out`` with ``save_pretrained`` (weights,
``config.json`` with the scene and the planning defaults stored in the checkpoint, ``README.md``
card). The shipped models are ``src/kinet_rl/models/weights/<name>``; the commands that shipped
them are in the README ("Pretrained models") and each card.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from omegaconf import OmegaConf

from kinet_rl.data import load_dataset
from kinet_rl.envs import SceneGeometry
from kinet_rl.evaluation.forward import forward_errors
from kinet_rl.models import KINetWorldModel
from kinet_rl.pipeline import CHECK_PROTOCOL, fresh_keypoint_accuracy

SEQUENCES, HORIZONS = 1024, (1, 5, 10)


def millimetres(errors: dict, key: str) -> dict[str, float]:
    return {str(h): round(1e3 * row[key], 1) for h, row in errors.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, required=True, help="a finished KINet run folder")
    parser.add_argument("--name", required=True, help="the shipped model's name")
    parser.add_argument("--out", type=Path, required=True, help="the new model folder")
    parser.add_argument("--command", required=True, help="the command that trained it")
    parser.add_argument("--hardware", required=True)
    parser.add_argument("--wall-time-s", type=int, required=True, help="training wall time")
    parser.add_argument("--description", required=True)
    parser.add_argument("--intended-use", required=True)
    parser.add_argument("--limits", required=True)
    args = parser.parse_args()

    model = KINetWorldModel.from_checkpoint(args.run / "kinet.pt").eval()
    cfg = OmegaConf.load(args.run / ".hydra" / "config.yaml")
    results = json.loads((args.run / "results.json").read_text())
    scene = model.scene
    dataset = Path(cfg.data.root) / cfg.data.name
    if not dataset.is_absolute():
        dataset = Path.cwd() / dataset
    test = load_dataset(dataset, "test")
    geometry = SceneGeometry.of_scene(scene.task, scene.camera, scene.image_size)
    errors = forward_errors(
        model.object_rollout(geometry), test, HORIZONS, SEQUENCES, seed=0,
        floor=model.detector_floor(geometry),
    )  # fmt: skip
    with tempfile.TemporaryDirectory() as work:
        start = time.perf_counter()
        check = fresh_keypoint_accuracy(model, scene, CHECK_PROTOCOL, Path(work), args.name)
        seconds = time.perf_counter() - start
    meta = test.metadata
    splits = {name: stop - start for name, (start, stop) in meta["splits"].items()}
    card = {
        "name": args.name,
        "description": args.description,
        "command": args.command,
        "seed": int(cfg.trainer.seed),
        "data": (
            f"data/{cfg.data.name}: {meta['num_episodes']:,} random-push episodes of "
            f"{meta['episode_length']} pushes ({splits.get('train', 0):,} train, "
            f"{splits.get('val', 0)} val, {splits.get('test', 0)} test), collection seed "
            f"{meta.get('seed', 0)}"
        ),
        "training": {
            "steps": int(results["step"]),
            "batch_size": int(cfg.trainer.batch_size),
            "hardware": args.hardware,
            "wall_time_s": args.wall_time_s,
        },
        "metrics": {
            "keypoint_accuracy": round(results["keypoint_accuracy"], 4),
            "hit_radius_px": results["hit_radius_px"],
            "forward_error_mm": millimetres(errors, "model"),
            "forward_error_moved_mm": millimetres(errors, "model_moved"),
            "no_motion_mm": millimetres(errors, "no_motion"),
            "detector_floor_mm": millimetres(errors, "floor"),
            "metrics_on": f"the dataset's {splits.get('test', 0)} test episodes "
            f"({SEQUENCES:,} sequences, seed 0), see docs/results.md",
        },
        "check": {
            **CHECK_PROTOCOL,
            "keypoint_accuracy": round(check, 4),
            "tolerance": 0.05,
            "measured": f"pretrained_keypoint_accuracy({args.name!r}, <tmp>) on "
            f"{args.hardware}, {seconds:.1f} s",
        },
        "intended_use": args.intended_use,
        "limits": args.limits,
        "license": "MIT (the package's)",
    }
    model.save_pretrained(args.out, card=card)
    print(json.dumps(card["metrics"] | {"check": card["check"]}, indent=2))


if __name__ == "__main__":
    main()
