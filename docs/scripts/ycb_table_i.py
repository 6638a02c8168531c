"""YCBObjs' Table I of one camera at 96 px (docs/results.md) from the JSON under docs/runs.

Every row of a camera was trained on the same data (`ycb_side96_cpu` or `ycb_top96_cpu`), scored
on the same 256 test sequences and planned on the same 100 test episodes. A row with several
training seeds shows the mean ± the half-width of the Student-t 95% interval over seeds
(``kinet_rl.stats.mean_interval``); a row with one seed shows its value, and its MPC `±` (marked
*) is over the 100 episodes.

Usage: python docs/scripts/ycb_table_i.py side|top
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from kinet_rl.stats import mean_interval

RUNS = Path(__file__).resolve().parents[1] / "runs"
KINET_COST = "kinet_keypoints_distance"
# row: (its name in docs/runs, planning method)
ROWS = {
    "KINet": ("kinet", KINET_COST),
    "KINet-determ": ("determ", KINET_COST),
    "KINet-no-ctr": ("no_ctr", KINET_COST),
    "V-CDN": ("vcdn", "model_mpc"),
    "ForwInv": ("forwinv", "model_mpc"),
    "Forw": ("forw", "model_mpc"),
    "IN (GT positions)": ("in", "model_mpc"),
    "IN-full (GT position, yaw, box)": ("in_full", "model_mpc"),
    "VisIN (GT positions + crops)": ("visin", "model_mpc"),
}
# camera: (the folders under docs/runs that hold its rows, KINet seed 0's results and
# rearrangement JSON where they sit elsewhere)
CAMERAS = {
    "side": (
        (RUNS / "ycb_side96_cpu_ablations", RUNS / "ycb_side96_cpu_seeds"),
        (
            RUNS / "ycb_side96_cpu/kinet_results.json",
            RUNS / "ycb_cost_validation/test_side96_rearrangement.json",
        ),
    ),
    "top": ((RUNS / "ycb_top96_cpu",), None),
}
SCORES = (
    ("1", "model"),
    ("1", "model_moved"),
    ("5", "model"),
    ("10", "model"),
    ("10", "model_moved"),
)


def seed_files(name: str, camera: str) -> list[tuple[Path, Path]]:
    """(results, rearrangement) JSON of every seed of a camera's row found under docs/runs."""
    folders, kinet_seed0 = CAMERAS[camera]
    found = []
    for seed in (0, 1, 2):
        if seed == 0 and name == "kinet" and kinet_seed0:
            found.append(kinet_seed0)
            continue
        tag = name if seed == 0 else f"{name}_seed{seed}"
        for folder in folders:
            if (folder / f"{tag}_results.json").exists():
                found.append((folder / f"{tag}_results.json", folder / f"{tag}_rearrangement.json"))
                break
    return found


def cell(values: list[float], scale: float = 1000.0) -> str:
    mean, half = mean_interval(values)
    return f"{mean * scale:.1f}" + ("" if half is None else f" ± {half * scale:.1f}")


def main(camera: str) -> None:
    if camera not in CAMERAS:
        raise SystemExit(f"usage: python {sys.argv[0]} {'|'.join(CAMERAS)} (got {camera!r})")
    rows = []
    for row, (name, method) in ROWS.items():
        files = seed_files(name, camera)
        if files:
            reports = [json.loads(r.read_text()) for r, _ in files]
            plans = [json.loads(m.read_text())["summary"]["comparison"][method] for _, m in files]
            rows.append((row, reports, plans))
    if not rows:
        raise SystemExit(f"no {camera} camera rows under {RUNS}: copy the runs there first")
    start = rows[0][2][0]["initial_distance"] * 1000
    header = "keypoint acc. | 1 push | 1 push, moved | 5 pushes | 10 pushes | 10 pushes, moved"
    print(
        f"| {camera} camera, 96 px [mm] | seeds | {header} | MPC final (start {start:.1f}) | success |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    floor = None
    for row, reports, plans in rows:
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
            f"| {row} | {len(reports)} | {accuracy} | {' | '.join(errors)} | {final} | {success:.1f}% |"
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
    main(sys.argv[1] if len(sys.argv) > 1 else "")
