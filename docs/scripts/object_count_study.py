"""The paper's Fig. 9c from rearrangement JSONs: final distance to the goal by object count.

One line per run (e.g. trained on 3 objects against trained on 1-5), with 95%-interval bars over
episodes.

Prints a markdown table (start distance, then each run's final distance ± interval and success
rate per object count) and saves the plot.

Usage, after the rows of ``python -m kinet_rl.tables -m tables=ycb_side96_cpu row=kinet,objects_1to5``
(their object counts are in each row's ``tables_mpc_64x3/rearrangement.json``)::

    R=runs/tables_ycb_side96_cpu
    python docs/scripts/object_count_study.py out.png \
        "trained on 3, seed 0=$R/ycb_sideview/tables_mpc_64x3/rearrangement.json" \
        "trained on 1-5, seed 0=$R/ycb_sideview_objects_1to5/tables_mpc_64x3/rearrangement.json"
"""

from __future__ import annotations

import argparse
from pathlib import Path

from object_count_curves import count_cells

from kinet_rl.evaluation.images import save_line_plot


def by_count(path: Path) -> dict[int, dict]:
    """Object count -> the summary cell of the run's KINet method, training geometry."""
    _, cells = count_cells(path)
    return {n: cell for (n, geometry), cell in cells.items() if geometry == "train"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("runs", nargs="+", help="LABEL=rearrangement.json")
    args = parser.parse_args()
    runs = {}
    for item in args.runs:
        label, sep, path = item.partition("=")
        if not sep:
            raise SystemExit(f"{item!r}: give each run as LABEL=path/to/rearrangement.json")
        runs[label] = by_count(Path(path))
    counts = sorted(set.intersection(*(set(cells) for cells in runs.values())))
    first = next(iter(runs.values()))
    print("| objects | start [mm] | " + " | ".join(runs) + " |")
    print("|---:|---:|" + "---:|" * len(runs))
    for n in counts:
        row = [
            f"{cells[n]['final_distance'] * 1e3:.1f} ± {cells[n]['final_distance_ci95'] * 1e3:.1f}"
            f" ({cells[n]['success_rate']:.0%})"
            for cells in runs.values()
        ]
        print(f"| {n} | {first[n]['initial_distance'] * 1e3:.1f} | " + " | ".join(row) + " |")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(counts, [first[n]["initial_distance"] * 1e3 for n in counts], "k--", label="start")
    for offset, (label, cells) in enumerate(runs.items()):
        shift = 0.08 * (offset - (len(runs) - 1) / 2)
        ax.errorbar(
            [n + shift for n in counts],
            [cells[n]["final_distance"] * 1e3 for n in counts],
            yerr=[cells[n]["final_distance_ci95"] * 1e3 for n in counts],
            marker="o",
            capsize=3,
            label=f"{label} (n={cells[counts[0]]['episodes']} per count)",
        )
    ax.set_xticks(counts)
    print(
        save_line_plot(
            fig,
            ax,
            args.out,
            "objects in the scene",
            "final mean object distance to goal [mm]",
            "MPC by object count (Fig. 9c)",
        )
    )


if __name__ == "__main__":
    main()
