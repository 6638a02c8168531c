"""The comparison tables of ``python -m kinet_rl.tables``: per-sequence forward errors, markdown, plot.

Units and protocol are the same for every row: Table I is the single-step forward error in
millimetres (mean ± std over the same held-out test sequences for every model of a camera); the
MPC table is the ground-truth mean object distance to the goal after ``T`` pushes (mean ± standard
error over the same episodes) and the success rate; Table II is KINet's MPC final distance per
object count and geometry.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import torch

from kinet_rl.evaluation.forward import ObjectRollout, start_frames
from kinet_rl.evaluation.metrics import position_error
from kinet_rl.keys import ACTION, OBJECT_POS
from kinet_rl.rearrangement.methods import METHODS
from kinet_rl.rearrangement.report import plot_curves
from kinet_rl.rearrangement.settings import generalization_key

#: Row labels of the tables.
LABELS = {
    "kinet": "KINet",
    "kinet_determ": "KINet-determ",
    "kinet_no_ctr": "KINet-no-ctr",
    "forw": "Forw",
    "forwinv": "ForwInv",
    "in": "IN (GT state)",
    "visin": "VisIN (GT state + image)",
    "random": METHODS["random"].label,
    "oracle": METHODS["oracle"].label,
}


@torch.no_grad()
def single_step_errors(
    rollout: ObjectRollout, dataset, num_sequences: int, seed: int = 0
) -> dict[str, dict[str, float]]:
    """Single-step position error of the model and of no motion, metres, mean and std over sequences.

    The sequences are drawn with ``seed`` (the same windows for every model of a dataset); a
    sequence's error is the mean over its objects.
    """
    seq = dataset.sample_sequences(num_sequences, 1, torch.Generator().manual_seed(seed))
    pred = rollout(start_frames(seq), seq[ACTION])[:, 0]  # [B, N, 2]
    truth = seq[OBJECT_POS]
    errors = {
        "model": position_error(pred, truth[:, 1]),
        "no_motion": position_error(truth[:, 0], truth[:, 1]),
    }
    return {
        name: {"mean": e.mean().item(), "std": e.std().item(), "sequences": e.numel()}
        for name, e in errors.items()
    }


def _mm(stats: Mapping[str, float] | None, mean: str = "mean", spread: str = "std") -> str:
    if stats is None:
        return "not run"
    return f"{stats[mean] * 1e3:.1f} ± {stats[spread] * 1e3:.1f}"


def table_i(
    forward: Mapping[str, Mapping[str, Any]], models: Sequence[str], cameras: Sequence[str]
) -> str:
    """Table I: single-step forward error (mm), ``forward[model][camera]`` from :func:`single_step_errors`."""
    lines = [
        "| model | " + " | ".join(f"{c} view (mm)" for c in cameras) + " |",
        "|---|" + "---:|" * len(cameras),
    ]
    for model in models:
        cells = [_mm(forward.get(model, {}).get(c, {}).get("model")) for c in cameras]
        lines.append(f"| {LABELS.get(model, model)} | " + " | ".join(cells) + " |")
    no_motion = []
    for camera in cameras:
        first = next((forward[m][camera] for m in models if camera in forward.get(m, {})), None)
        no_motion.append(_mm(None if first is None else first["no_motion"]))
    lines.append("| No motion | " + " | ".join(no_motion) + " |")
    return "\n".join(lines)


def mpc_table(
    mpc: Mapping[str, Mapping[str, Any]],
    rows: Sequence[str],
    num_steps: int,
    kinet_method: str,
) -> str:
    """MPC table: final distance (mm, mean ± s.e.) and success rate; ``mpc[row]`` = episode stats.

    ``kinet_method`` names the planner of the KINet rows (``kinet_graph`` or ``kinet_graph_distance``).
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
            f"{_mm(stats, 'final_distance', 'final_distance_sem')} | "
            f"{100 * stats['success_rate']:.0f}% |"
        )
    return "\n".join(lines)


def _planner(row: str, kinet_method: str) -> str:
    if row.startswith("kinet"):
        return METHODS[kinet_method].label
    if row in ("forw", "forwinv"):
        return "MPC on goal-image feature distance"
    if row in ("in", "visin", "oracle"):
        return "MPC on GT goal distance"
    return "-"


def table_ii(
    cells: Mapping[str, Mapping[str, Any]],
    models: Sequence[str],
    num_objects: Sequence[int],
    geometries: Sequence[str],
) -> str:
    """Table II: MPC final distance (mm, mean ± s.e.) per object count; ``cells[model][cell]``.

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
                "final_distance_sem",
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


def plot_mpc_curves(mpc: Mapping[str, Mapping[str, Any]], path: Path) -> Path:
    """Mean distance to the goal (mm) after each push, one curve per row, with s.e. bands."""
    return plot_curves(dict(mpc), LABELS, path, "MPC: distance to goal")
