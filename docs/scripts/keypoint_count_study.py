"""The paper's Fig. 9b from training reports and rearrangement JSONs: scores by keypoint count K.

Each ``--run K SEED RESULTS REARRANGEMENT`` names one trained model: its training report
(``results.json``: keypoint accuracy, forward errors of the model, no motion and detector floor)
and its rearrangement JSON (final distance to the goal of ``--method``). Prints a markdown table
(one row per run), a second table over the training seeds of each K (mean and 95% interval,
Student's t) and saves a plot of the final distance against K: each run with its 95%-interval
bars over episodes, the mean over seeds and the mean start distance.

Usage, after the rows of ``python -m kinet_rl.tables -m tables=ycb_side96_cpu row=kinet,k3,k6,k12``
(each row's run ``runs/tables_ycb_side96_cpu/<run>[_seed<s>]``, its MPC under ``tables_mpc_64x3/``)::

    R=runs/tables_ycb_side96_cpu
    python docs/scripts/keypoint_count_study.py out.png \
        --run 3 0 $R/ycb_sideview_k3/results.json $R/ycb_sideview_k3/tables_mpc_64x3/rearrangement.json \
        --run 9 0 $R/ycb_sideview/results.json $R/ycb_sideview/tables_mpc_64x3/rearrangement.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from kinet_rl.evaluation.images import save_line_plot
from kinet_rl.stats import mean_interval


def row(k: int, seed: int, results: Path, rearrangement: Path, method: str) -> dict:
    """One run's scores in mm (forward errors of the test split, MPC final distance)."""
    report = json.loads(results.read_text())
    comparison = json.loads(rearrangement.read_text())["summary"]["comparison"]
    if method not in comparison:
        raise SystemExit(f"{rearrangement} has no method {method!r}; it has {sorted(comparison)}")
    mpc = comparison[method]
    errors = report["forward_errors_m"]
    return {
        "k": k,
        "seed": seed,
        "accuracy": report["keypoint_accuracy"] * 100,
        "one": errors["1"]["model"] * 1e3,
        "one_moved": errors["1"]["model_moved"] * 1e3,
        "ten": errors["10"]["model"] * 1e3,
        "floor": errors["1"]["floor"] * 1e3,
        "no_motion": (errors["1"]["no_motion"] * 1e3, errors["10"]["no_motion"] * 1e3),
        "start": mpc["initial_distance"] * 1e3,
        "horizon": len(mpc["mean_curve"]) - 1,
        "final": mpc["final_distance"] * 1e3,
        "final_ci": mpc["final_distance_ci95"] * 1e3,
        "success": mpc["success_rate"],
        "episodes": mpc["episodes"],
    }


def over_seeds(values: list[float]) -> str:
    """Mean and 95% interval over seeds (a single seed has no interval)."""
    mean, half = mean_interval(values)
    return f"{mean:.1f}" if half is None else f"{mean:.1f} ± {half:.1f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument(
        "--run", nargs=4, action="append", required=True, metavar=("K", "SEED", "RESULTS", "MPC")
    )
    parser.add_argument("--method", default="kinet_keypoints_distance")
    args = parser.parse_args()
    rows = sorted(
        (row(int(k), int(s), Path(r), Path(m), args.method) for k, s, r, m in args.run),
        key=lambda r: (r["k"], r["seed"]),
    )
    print(
        "| K | seed | keypoint accuracy | 1 push [mm] | 1 push, moved | 10 pushes | "
        "detector floor, 1 push | MPC final [mm] | MPC success |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['k']} | {r['seed']} | {r['accuracy']:.1f}% | {r['one']:.1f} | "
            f"{r['one_moved']:.1f} | {r['ten']:.1f} | {r['floor']:.1f} | "
            f"{r['final']:.1f} ± {r['final_ci']:.1f} | {r['success']:.0%} |"
        )
    print(
        f"\nno motion: {rows[0]['no_motion'][0]:.1f} / {rows[0]['no_motion'][1]:.1f} mm "
        f"(1 / 10 pushes); MPC start {rows[0]['start']:.1f} mm, {rows[0]['episodes']} episodes"
    )
    ks = sorted({r["k"] for r in rows})
    by_k = {k: [r for r in rows if r["k"] == k] for k in ks}
    print("\nover training seeds (mean ± 95% interval, Student's t):\n")
    print("| K | seeds | keypoint accuracy [%] | 1 push [mm] | 1 push, moved | MPC final [mm] |")
    print("|---:|---:|---:|---:|---:|---:|")
    for k, mine in by_k.items():
        cells = [
            over_seeds([r[key] for r in mine]) for key in ("accuracy", "one", "one_moved", "final")
        ]
        print(f"| {k} | {len(mine)} | " + " | ".join(cells) + " |")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(ks, [rows[0]["start"]] * len(ks), "k--", label="start")
    means = [mean_interval([r["final"] for r in by_k[k]])[0] for k in ks]
    ax.plot(ks, means, "k-", linewidth=2, label="mean over seeds")
    for seed in sorted({r["seed"] for r in rows}):
        mine = [r for r in rows if r["seed"] == seed]
        ax.errorbar(
            [r["k"] + 0.1 * seed for r in mine],
            [r["final"] for r in mine],
            yerr=[r["final_ci"] for r in mine],
            marker="o",
            capsize=3,
            linestyle="none",
            label=f"seed {seed} (n={mine[0]['episodes']} episodes)",
        )
    ax.set_xticks(ks)
    print(
        save_line_plot(
            fig,
            ax,
            args.out,
            "keypoints K",
            "final mean object distance to goal [mm]",
            f"MPC by keypoint count (Fig. 9b), T = {rows[0]['horizon']}",
        )
    )


if __name__ == "__main__":
    main()
