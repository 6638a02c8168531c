"""Mean and 95% interval over training seeds of one model's scores (docs/results.md).

Reads each seed's training report (``<run dir>/results.json``: keypoint accuracy, forward error
of the model, of no motion and of the detector floor after 1, 5 and 10 pushes, all objects and
moved objects) and, where given, each seed's rearrangement JSON (final distance to the goal of
``--method``), and prints one markdown line per score: the per-seed values and their mean ±
the half-width of the Student-t 95% interval over seeds (``kinet_rl.stats.mean_interval``).

Usage: python docs/scripts/seed_rows.py --runs runs/a runs/a_seed1 runs/a_seed2 \
    --mpc runs/a/rearrangement/rearrangement.json ... --method kinet_keypoints_distance
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from kinet_rl.stats import mean_interval

FORWARD = ("model", "model_moved", "floor", "floor_moved", "no_motion")


def line(name: str, values: list[float], scale: float, digits: int) -> str:
    mean, half = mean_interval(values)
    spread = "" if half is None else f" ± {half * scale:.{digits}f}"
    seeds = ", ".join(f"{v * scale:.{digits}f}" for v in values)
    return f"| {name} | {seeds} | {mean * scale:.{digits}f}{spread} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=Path, nargs="+", required=True)
    parser.add_argument("--mpc", type=Path, nargs="*", default=[])
    parser.add_argument("--method", default="kinet_keypoints_distance")
    args = parser.parse_args()
    reports = [json.loads((run / "results.json").read_text()) for run in args.runs]
    print(f"| score ({len(reports)} seeds) | per seed | mean ± 95% interval over seeds |")
    print("|---|---|---:|")
    if all("keypoint_accuracy" in r for r in reports):
        print(line("keypoint accuracy [%]", [r["keypoint_accuracy"] for r in reports], 100, 1))
    for horizon in sorted(reports[0]["forward_errors_m"], key=int):
        for key in FORWARD:
            values = [r["forward_errors_m"][horizon].get(key) for r in reports]
            if None not in values:
                print(line(f"{key}, {horizon} push(es) [mm]", values, 1000, 1))
    if args.mpc:
        finals = [
            json.loads(path.read_text())["summary"]["comparison"][args.method]["final_distance"]
            for path in args.mpc
        ]
        print(line(f"MPC final distance, {args.method} [mm]", finals, 1000, 1))


if __name__ == "__main__":
    main()
