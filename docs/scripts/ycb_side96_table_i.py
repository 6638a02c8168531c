"""Table I of YCBObjs' side camera at 96 px (docs/results.md) from the JSON under docs/runs.

Every row was trained on the same data (`ycb_side96_cpu`), scored on the same 256 test sequences
and planned on the same 100 test episodes. A row with several training seeds shows the mean ± the
half-width of the Student-t 95% interval over seeds (``kinet_rl.stats.mean_interval``); a row with
one seed shows its value, and its MPC `±` (marked *) is over the 100 episodes.

Usage: python docs/scripts/ycb_side96_table_i.py
"""

from __future__ import annotations

import json
from pathlib import Path

from kinet_rl.stats import mean_interval

RUNS = Path(__file__).resolve().parents[1] / "runs"
SEEDS, ABLATIONS = RUNS / "ycb_side96_cpu_seeds", RUNS / "ycb_side96_cpu_ablations"
KINET_COST = "kinet_keypoints_distance"
# row: (its name in docs/runs, planning method, seed 0's results.json, seed 0's rearrangement.json)
ROWS = {
    "KINet": (
        "kinet",
        KINET_COST,
        RUNS / "ycb_side96_cpu/kinet_results.json",
        RUNS / "ycb_cost_validation/test_side96_rearrangement.json",
    ),
    "KINet-determ": ("determ", KINET_COST, None, None),
    "KINet-no-ctr": ("no_ctr", KINET_COST, None, None),
    "V-CDN": ("vcdn", "model_mpc", None, None),
    "ForwInv": ("forwinv", "model_mpc", None, None),
    "Forw": ("forw", "model_mpc", None, None),
    "IN (GT positions)": ("in", "model_mpc", None, None),
    "IN-full (GT position, yaw, box)": ("in_full", "model_mpc", None, None),
    "VisIN (GT positions + crops)": ("visin", "model_mpc", None, None),
}
SCORES = (
    ("1", "model"),
    ("1", "model_moved"),
    ("5", "model"),
    ("10", "model"),
    ("10", "model_moved"),
)


def seed_files(name: str, results: Path | None, mpc: Path | None) -> list[tuple[Path, Path]]:
    """(results, rearrangement) JSON of every seed of a row found under docs/runs."""
    found = [(results, mpc)] if results else []
    for seed in (0, 1, 2):
        tag = name if seed == 0 else f"{name}_seed{seed}"
        for folder in (ABLATIONS, SEEDS):
            if (folder / f"{tag}_results.json").exists() and not (seed == 0 and results):
                found.append((folder / f"{tag}_results.json", folder / f"{tag}_rearrangement.json"))
                break
    return found


def cell(values: list[float], scale: float = 1000.0) -> str:
    mean, half = mean_interval(values)
    return f"{mean * scale:.1f}" + ("" if half is None else f" ± {half * scale:.1f}")


def main() -> None:
    header = "keypoint acc. | 1 push | 1 push, moved | 5 pushes | 10 pushes | 10 pushes, moved"
    print(f"| side camera, 96 px [mm] | seeds | {header} | MPC final (start 85.2) | success |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    floor = None
    for row, (name, method, results, mpc) in ROWS.items():
        files = seed_files(name, results, mpc)
        if not files:
            continue
        reports = [json.loads(r.read_text()) for r, _ in files]
        plans = [json.loads(m.read_text())["summary"]["comparison"][method] for _, m in files]
        errors = [cell([r["forward_errors_m"][h][k] for r in reports]) for h, k in SCORES]
        accuracy = (
            cell([r["keypoint_accuracy"] for r in reports], 100.0) + "%"
            if "keypoint_accuracy" in reports[0]
            else "-"
        )
        final = cell([p["final_distance"] for p in plans])
        if len(plans) == 1:
            final += f" ± {plans[0]['final_distance_ci95'] * 1000:.1f}*"
        success = 100 * sum(p["success_rate"] for p in plans) / len(plans)
        print(
            f"| {row} | {len(files)} | {accuracy} | {' | '.join(errors)} | {final} | {success:.1f}% |"
        )
        floor = floor or reports
    floors = [
        cell([r["forward_errors_m"][h][k.replace("model", "floor")] for r in floor])
        for h, k in SCORES
    ]
    print(f"| detector floor (KINet's seeds) | {len(floor)} | - | {' | '.join(floors)} | - | - |")
    still = floor[0]["forward_errors_m"]
    no_motion = [f"{still[h][k.replace('model', 'no_motion')] * 1000:.1f}" for h, k in SCORES]
    print(f"| no motion | - | - | {' | '.join(no_motion)} | - | - |")


if __name__ == "__main__":
    main()
