"""Forward error of a trained model against a dataset's object state:
``python docs/scripts/forward_error.py --checkpoint runs/<exp>/kinet.pt --dataset data/<name>``.

Table I's measure (``kinet_rl.evaluation.forward.forward_errors``: object-position error after
1, 5 and 10 pushes from the start frame alone and the logged pushes, beside no motion; test
sequences drawn with seed 0, the same for every model) for a model trained on other data, e.g. on
the same episodes exported to LeRobot v3 without their object state and imported
(docs/results.md, "Trained without object state"). The geometry is the dataset's scene (its
``metadata.json``). Prints the markdown table; ``--out`` also writes the JSON (metres).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinet_rl.atomic import atomic_write_json
from kinet_rl.data import load_dataset
from kinet_rl.envs import SceneGeometry
from kinet_rl.evaluation.forward import forward_errors, forward_table
from kinet_rl.pipeline import check_dataset_for
from kinet_rl.rows import load_trained_model


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--checkpoint", type=Path, required=True, help="kinet.pt, model.pt or a model folder"
    )
    parser.add_argument("--dataset", type=Path, required=True, help="a dataset with object state")
    parser.add_argument("--split", default="test")
    parser.add_argument("--horizons", type=int, nargs="+", default=[1, 5, 10])
    parser.add_argument("--sequences", type=int, default=1024, help="Table I: 1,024")
    parser.add_argument("--out", type=Path, default=None, help="JSON file to write")
    args = parser.parse_args()
    model = load_trained_model(args.checkpoint)
    data = load_dataset(args.dataset, args.split)
    check_dataset_for(model, data)
    env = data.metadata["env"]
    geometry = SceneGeometry.of_scene(env["task"], env["camera"], data.image_size)
    errors = forward_errors(
        model.object_rollout(geometry), data, tuple(args.horizons), args.sequences, seed=0
    )
    print(forward_table(errors, name=type(model).__name__))
    if args.out is not None:
        atomic_write_json(args.out, errors)


if __name__ == "__main__":
    main()
