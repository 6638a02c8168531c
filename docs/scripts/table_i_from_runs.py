"""Table I of docs/results.md from the per-row JSON of one or more `kinet_rl.tables` run folders.

Rows trained by separate `kinet_rl.tables` commands (e.g. the ablations, run as their own jobs)
live in separate folders; this collects every `<exp_name>[_seed<s>]/tables_forward.json` found
under the folders given and prints the tables of `kinet_rl.tables` (all objects, moved objects,
moved objects after several pushes) for the rows and seeds found. Every row must have been
scored on the same test sequences (same data, same `forward_sequences`, sequence seed 0).

Usage: python docs/scripts/table_i_from_runs.py docs/runs/tables_cpu docs/runs/tables_cpu_ablations
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

from kinet_rl.comparison import horizon_table, table_i
from kinet_rl.rows import ROWS
from kinet_rl.tables import CAMERAS, TASKS

ROW = re.compile(
    rf"(?P<task>{'|'.join(TASKS)})_(?P<camera>{'|'.join(CAMERAS)})view(?P<suffix>[a-z_]*?)"
    r"(?:_seed(?P<seed>\d+))?"
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", type=Path, nargs="+")
    parser.add_argument("--horizons", type=int, nargs="+", default=[1, 5, 10])
    args = parser.parse_args()
    model_of = {row.experiment_suffix: name for name, row in ROWS.items()}
    found: dict[str, dict[str, dict[int, dict]]] = {}
    for folder in args.folders:
        for path in sorted(folder.glob("*/tables_forward.json")):
            match = ROW.fullmatch(path.parent.name)
            if match is None or match["suffix"] not in model_of:
                continue
            model, camera = model_of[match["suffix"]], match["camera"]
            seed = int(match["seed"] or 0)
            found.setdefault(model, {}).setdefault(camera, {})[seed] = json.loads(path.read_text())
    forward = {
        model: {camera: [seeds[s] for s in sorted(seeds)] for camera, seeds in cams.items()}
        for model, cams in found.items()
    }
    models = [m for m in ROWS if m in forward]
    cameras = [c for c in CAMERAS if any(c in cams for cams in forward.values())]
    for model in models:
        seeds = {c: sorted(found[model][c]) for c in cameras if c in found[model]}
        print(f"<!-- {model}: seeds {seeds} -->")
    print("\nAll objects, 1 push:\n")
    print(table_i(forward, models, cameras))
    print("\nMoved objects, 1 push:\n")
    print(table_i(forward, models, cameras, subset="_moved"))
    for camera in cameras:
        print(f"\nMoved objects after several pushes, {camera} camera:\n")
        print(horizon_table(forward, models, camera, args.horizons))


if __name__ == "__main__":
    main()
