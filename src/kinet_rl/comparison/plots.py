"""The comparison's plots: learning curves and MPC distance curves."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from kinet_rl.comparison.markdown import SeedStats, label_of
from kinet_rl.evaluation.images import save_line_plot
from kinet_rl.rearrangement.report import plot_curves
from kinet_rl.rows import ROWS, Row

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


def plot_mpc_curves(
    mpc: Mapping[str, SeedStats], path: Path, registry: Mapping[str, Row] = ROWS
) -> Path:
    """Mean distance to the goal (mm) after each push, one curve per row (its first seed's),
    with 95%-interval bands."""
    labels = {row: label_of(row, registry) for row in mpc}
    first = {row: per_seed[0] for row, per_seed in mpc.items() if per_seed}
    return plot_curves(first, labels, path, "MPC: distance to goal")
