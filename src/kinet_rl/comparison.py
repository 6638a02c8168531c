"""The comparison tables of ``python -m kinet_rl.tables``: forward errors over seeds, markdown, plot.

Units and protocol are the same for every row: Table I is the forward error in millimetres on the
same held-out test sequences for every model of a camera, averaged over the sequences of each
training seed, then mean ± 95% interval (Student's t) over training seeds; the detector floor
reads object motion off the keypoints KINet detects in the true next frames. The MPC table is the
ground-truth mean object distance to the goal after ``T`` pushes (mean ± 95% interval over the
same episodes) and the success rate with its Wilson interval; Table II is the MPC final distance of
the generalization models (KINet, KINet-determ, V-CDN) per object count and geometry.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from kinet_rl.evaluation.images import save_line_plot
from kinet_rl.rearrangement.methods import METHODS
from kinet_rl.rearrangement.report import plot_curves, success_text
from kinet_rl.rearrangement.settings import generalization_key
from kinet_rl.rows import ROWS
from kinet_rl.stats import mean_interval

#: Row labels of the tables: the comparison rows, random pushes and the oracle.
LABELS = {
    **{name: row.label for name, row in ROWS.items()},
    "random": METHODS["random"].label,
    "oracle": METHODS["oracle"].label,
}


#: A row's forward errors: one :func:`~kinet_rl.evaluation.forward.forward_errors` dict per seed.
SeedErrors = Sequence[Mapping[str, Mapping[str, float]]]


def _forward_cell(per_seed: SeedErrors | None, horizon: int, key: str) -> str:
    values = [seed[str(horizon)][key] for seed in per_seed or () if key in seed[str(horizon)]]
    if not values:
        return "not run"
    mean, half = mean_interval(values)
    return f"{mean * 1e3:.1f}" if half is None else f"{mean * 1e3:.1f} ± {half * 1e3:.1f}"


def table_i(
    forward: Mapping[str, Mapping[str, SeedErrors]],
    models: Sequence[str],
    cameras: Sequence[str],
    horizon: int = 1,
    subset: str = "",
) -> str:
    """Table I: forward error (mm) after ``horizon`` pushes; ``forward[model][camera]`` per seed.

    Rows: every model, the detector floor (KINet's own detector, same seeds) and no motion.
    ``subset`` ``"_moved"`` or ``"_unmoved"`` scores only objects that moved or stayed.
    """
    lines = [
        "| model | " + " | ".join(f"{c} view (mm)" for c in cameras) + " |",
        "|---|" + "---:|" * len(cameras),
    ]
    for model in models:
        cells = [
            _forward_cell(forward.get(model, {}).get(c), horizon, f"model{subset}") for c in cameras
        ]
        lines.append(f"| {LABELS.get(model, model)} | " + " | ".join(cells) + " |")
    floors = [
        _forward_cell(forward.get("kinet", {}).get(c), horizon, f"floor{subset}") for c in cameras
    ]
    lines.append(
        "| Detector floor (KINet's keypoints of the true frames) | " + " | ".join(floors) + " |"
    )
    if subset != "_unmoved":
        no_motion = []
        for camera in cameras:
            rows = [forward[m][camera] for m in models if camera in forward.get(m, {})]
            no_motion.append(
                _forward_cell(rows[0][:1] if rows else None, horizon, f"no_motion{subset}")
            )
        lines.append("| No motion | " + " | ".join(no_motion) + " |")
    return "\n".join(lines)


def horizon_table(
    forward: Mapping[str, Mapping[str, SeedErrors]],
    models: Sequence[str],
    camera: str,
    horizons: Sequence[int],
) -> str:
    """Forward error (mm) on moved objects after each of ``horizons`` pushes, one camera."""
    lines = [
        "| model | " + " | ".join(f"{h} push{'es' if h > 1 else ''} (mm)" for h in horizons) + " |",
        "|---|" + "---:|" * len(horizons),
    ]
    for model in models:
        per_seed = forward.get(model, {}).get(camera)
        cells = [_forward_cell(per_seed, h, "model_moved") for h in horizons]
        lines.append(f"| {LABELS.get(model, model)} | " + " | ".join(cells) + " |")
    kinet = forward.get("kinet", {}).get(camera)
    lines.append(
        "| Detector floor | "
        + " | ".join(_forward_cell(kinet, h, "floor_moved") for h in horizons)
        + " |"
    )
    first = next((forward[m][camera] for m in models if camera in forward.get(m, {})), None)
    still = [
        _forward_cell(None if first is None else first[:1], h, "no_motion_moved") for h in horizons
    ]
    lines.append("| No motion | " + " | ".join(still) + " |")
    return "\n".join(lines)


def _mm(stats: Mapping[str, float] | None, mean: str = "mean", spread: str = "std") -> str:
    if stats is None:
        return "not run"
    return f"{stats[mean] * 1e3:.1f} ± {stats[spread] * 1e3:.1f}"


def mpc_table(
    mpc: Mapping[str, Mapping[str, Any]],
    rows: Sequence[str],
    num_steps: int,
    kinet_method: str,
) -> str:
    """MPC table: final distance (mm, mean ± 95% interval) and success rate; ``mpc[row]`` = episode stats.

    ``kinet_method`` names the planner of the KINet rows (a KINet method of ``METHODS``).
    """
    lines = [
        f"| model | planner | episodes | start (mm) | after T = {num_steps} (mm) | success |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for row in rows:
        stats = mpc.get(row)
        planner = _planner(row, kinet_method)
        if stats is None:
            lines.append(f"| {LABELS.get(row, row)} | {planner} | - | - | not run | - |")
            continue
        lines.append(
            f"| {LABELS.get(row, row)} | {planner} | {stats['episodes']} | "
            f"{stats['initial_distance'] * 1e3:.1f} | "
            f"{_mm(stats, 'final_distance', 'final_distance_ci95')} | {success_text(stats)} |"
        )
    return "\n".join(lines)


def _planner(row: str, kinet_method: str) -> str:
    if row == "oracle":
        return "MPC on GT goal distance"
    if row not in ROWS:
        return "-"
    return ROWS[row].planner_label or METHODS[ROWS[row].method or kinet_method].label


def table_ii(
    cells: Mapping[str, Mapping[str, Any]],
    models: Sequence[str],
    num_objects: Sequence[int],
    geometries: Sequence[str],
) -> str:
    """Table II: MPC final distance (mm, mean ± 95% interval) per object count; ``cells[model][cell]``.

    One ``start`` column per geometry gives the episodes' initial distance (the same episodes for
    every model), so that a final distance can be read as an improvement or not.
    """
    columns = [(m, g) for m in models for g in geometries]
    lines = [
        "| objects | "
        + " | ".join(f"start {g} geom. (mm)" for g in geometries)
        + " | "
        + " | ".join(f"{LABELS.get(m, m)} {g} geom. (mm)" for m, g in columns)
        + " |",
        "|---:|" + "---:|" * (len(geometries) + len(columns)),
    ]
    for n in num_objects:
        starts = [_initial_distance(cells, models, generalization_key(n, g)) for g in geometries]
        finals = [
            _mm(
                cells.get(m, {}).get(generalization_key(n, g)),
                "final_distance",
                "final_distance_ci95",
            )
            for m, g in columns
        ]
        lines.append(f"| {n} | " + " | ".join(starts + finals) + " |")
    return "\n".join(lines)


def _initial_distance(
    cells: Mapping[str, Mapping[str, Any]], models: Sequence[str], cell: str
) -> str:
    for model in models:
        stats = cells.get(model, {}).get(cell)
        if stats is not None:
            return f"{stats['initial_distance'] * 1e3:.1f}"
    return "-"


#: The learning-curve scalar of every run (written by :meth:`TrainingReport.on_validate`).
CURVE_FILE = "val/forward_error_1_mm.csv"


def learning_curve(run_dir: Path) -> list[tuple[int, float]]:
    """``(step, 1-push validation forward error in mm)`` pairs of a run's CSV log (empty if none)."""
    path = next(iter(sorted(Path(run_dir).rglob(CURVE_FILE))), None)
    if path is None:
        return []
    pairs = (line.split(",") for line in path.read_text().split())
    return [(int(float(step)), float(value)) for step, value in pairs]


def plot_learning_curves(runs: Mapping[str, Sequence[Path]], path: Path, title: str) -> Path:
    """1-push validation forward error (mm) against training steps, one line per run.

    ``runs`` maps a row label to its run directories (one per seed; each seed is drawn).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for i, (label, dirs) in enumerate(runs.items()):
        for j, run_dir in enumerate(dirs):
            curve = learning_curve(run_dir)
            if curve:
                steps, errors = zip(*curve, strict=True)
                label_once = label if j == 0 else None
                ax.plot(steps, errors, "o-", ms=3, color=f"C{i}", alpha=0.8, label=label_once)
    return save_line_plot(
        fig, ax, path, "training step", "1-push validation forward error [mm]", title
    )


def plot_mpc_curves(mpc: Mapping[str, Mapping[str, Any]], path: Path) -> Path:
    """Mean distance to the goal (mm) after each push, one curve per row, with 95%-interval bands."""
    return plot_curves(dict(mpc), LABELS, path, "MPC: distance to goal")
