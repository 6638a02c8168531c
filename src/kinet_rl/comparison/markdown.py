"""The comparison tables as markdown: Table I over seeds, MPC, Table II, backgrounds, keypoint
accuracy."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from kinet_rl.comparison.settings import LABELS, TablesSettings
from kinet_rl.rearrangement.methods import METHODS
from kinet_rl.rearrangement.report import success_text
from kinet_rl.rearrangement.settings import generalization_key
from kinet_rl.rows import ROWS, Row
from kinet_rl.stats import mean_interval

#: A row's forward errors: one :func:`~kinet_rl.evaluation.forward.forward_errors` dict per seed.
SeedErrors = Sequence[Mapping[str, Mapping[str, float]]]
#: A row's MPC stats of one condition: one episode summary per training seed that planned.
SeedStats = Sequence[Mapping[str, Any]]


def label_of(name: str, registry: Mapping[str, Row] = ROWS) -> str:
    """How the tables name a row (of ``registry``), random pushes or the oracle."""
    return registry[name].label if name in registry else LABELS.get(name, name)


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
    registry: Mapping[str, Row] = ROWS,
) -> str:
    """Table I: forward error (mm) after ``horizon`` pushes; ``forward[model][camera]`` per seed.

    Rows: every model, the detector floor (KINet's own detector, same seeds) and no motion.
    ``subset`` ``"_moved"`` or ``"_unmoved"`` scores only objects that moved or stayed;
    ``registry`` names the rows.
    """
    lines = [
        "| model | " + " | ".join(f"{c} view (mm)" for c in cameras) + " |",
        "|---|" + "---:|" * len(cameras),
    ]
    for model in models:
        cells = [
            _forward_cell(forward.get(model, {}).get(c), horizon, f"model{subset}") for c in cameras
        ]
        lines.append(f"| {label_of(model, registry)} | " + " | ".join(cells) + " |")
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
    registry: Mapping[str, Row] = ROWS,
) -> str:
    """Forward error (mm) on moved objects after each of ``horizons`` pushes, one camera."""
    lines = [
        "| model | " + " | ".join(f"{h} push{'es' if h > 1 else ''} (mm)" for h in horizons) + " |",
        "|---|" + "---:|" * len(horizons),
    ]
    for model in models:
        per_seed = forward.get(model, {}).get(camera)
        cells = [_forward_cell(per_seed, h, "model_moved") for h in horizons]
        lines.append(f"| {label_of(model, registry)} | " + " | ".join(cells) + " |")
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


def _final(per_seed: SeedStats | None) -> str:
    """Final distance (mm): one seed's mean ± 95% interval over episodes; with several seeds the
    mean ± 95% interval over seeds (Student's t) and each seed's value."""
    if not per_seed:
        return "not run"
    if len(per_seed) == 1:
        return _mm(per_seed[0], "final_distance", "final_distance_ci95")
    finals = [s["final_distance"] * 1e3 for s in per_seed]
    mean, half = mean_interval(finals)
    seeds = " / ".join(f"{f:.1f}" for f in finals)
    return f"{mean:.1f} ± {half:.1f} (seeds: {seeds})"


def _success(per_seed: SeedStats) -> str:
    if len(per_seed) == 1:
        return success_text(per_seed[0])
    rate = sum(s["success_rate"] for s in per_seed) / len(per_seed)
    return f"{100 * rate:.1f}% (mean of {len(per_seed)} seeds)"


def mpc_table(
    mpc: Mapping[str, SeedStats],
    rows: Sequence[str],
    num_steps: int,
    kinet_method: str,
    registry: Mapping[str, Row] = ROWS,
) -> str:
    """MPC table: final distance (mm) and success rate; ``mpc[row]`` = episode stats per seed.

    One seed: mean ± 95% interval over episodes and the success rate with its Wilson interval;
    several: mean ± 95% interval over seeds, each seed's final distance and the mean success
    rate. ``kinet_method`` names the planner of the KINet rows (a KINet method of ``METHODS``).
    """
    lines = [
        f"| model | planner | episodes | start (mm) | after T = {num_steps} (mm) | success |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for row in rows:
        per_seed = mpc.get(row)
        planner = _planner(row, kinet_method, registry)
        if not per_seed:
            lines.append(f"| {label_of(row, registry)} | {planner} | - | - | not run | - |")
            continue
        first = per_seed[0]
        episodes = str(first["episodes"])
        if len(per_seed) > 1:
            episodes += f" x {len(per_seed)} seeds"
        lines.append(
            f"| {label_of(row, registry)} | {planner} | {episodes} | "
            f"{first['initial_distance'] * 1e3:.1f} | {_final(per_seed)} | {_success(per_seed)} |"
        )
    return "\n".join(lines)


def _planner(row: str, kinet_method: str, registry: Mapping[str, Row] = ROWS) -> str:
    if row == "oracle":
        return "MPC on GT goal distance"
    if row not in registry:
        return "-"
    return registry[row].planner_label or METHODS[registry[row].method or kinet_method].label


def table_ii(
    cells: Mapping[str, Mapping[str, SeedStats]],
    models: Sequence[str],
    num_objects: Sequence[int],
    geometries: Sequence[str],
    registry: Mapping[str, Row] = ROWS,
) -> str:
    """Table II: MPC final distance (mm) per object count; ``cells[model][cell]`` per seed (one
    seed: mean ± 95% interval over episodes; several: over seeds, and each seed's value).

    One ``start`` column per geometry gives the episodes' initial distance (the same episodes for
    every model), so that a final distance can be read as an improvement or not.
    """
    columns = [(m, g) for m in models for g in geometries]
    lines = [
        "| objects | "
        + " | ".join(f"start {g} geom. (mm)" for g in geometries)
        + " | "
        + " | ".join(f"{label_of(m, registry)} {g} geom. (mm)" for m, g in columns)
        + " |",
        "|---:|" + "---:|" * (len(geometries) + len(columns)),
    ]
    for n in num_objects:
        starts = [_initial_distance(cells, models, generalization_key(n, g)) for g in geometries]
        finals = [_final(cells.get(m, {}).get(generalization_key(n, g))) for m, g in columns]
        lines.append(f"| {n} | " + " | ".join(starts + finals) + " |")
    return "\n".join(lines)


def background_table(
    comparison: Mapping[str, SeedStats],
    cells: Mapping[str, Mapping[str, SeedStats]],
    models: Sequence[str],
    backgrounds: Sequence[str],
    registry: Mapping[str, Row] = ROWS,
) -> str:
    """The backgrounds (the paper's Fig. 4b): MPC final distance (mm) of each model on the
    table's own scene (its MPC table's episodes, ``comparison[model]``) and on each background
    (``cells[model]["background_<name>"]``), and random pushes on each background's episodes
    (``cells[model]["background_<name>/random"]``, the same for every model)."""
    keys = [f"background_{b}" for b in backgrounds]

    def stats(model: str, key: str) -> SeedStats | None:
        return comparison.get(model) if key == "comparison" else cells.get(model, {}).get(key)

    def first(key: str) -> SeedStats | None:
        return next((found for m in models if (found := stats(m, key))), None)

    lines = [
        "| model | table's scene (mm) | "
        + " | ".join(f"{b} background (mm)" for b in backgrounds)
        + " |",
        "|---|---:|" + "---:|" * len(backgrounds),
    ]
    starts = []
    for key in ["comparison", *keys]:
        per_seed = first(key)
        starts.append("-" if not per_seed else f"{per_seed[0]['initial_distance'] * 1e3:.1f}")
    lines.append("| start | " + " | ".join(starts) + " |")
    for model in models:
        finals = [_final(stats(model, key)) for key in ["comparison", *keys]]
        lines.append(f"| {label_of(model, registry)} | " + " | ".join(finals) + " |")
    pushes = []
    for key in keys:
        per_seed = first(f"{key}/random")
        pushes.append("-" if not per_seed else _final(per_seed[:1]))
    lines.append(f"| {LABELS['random']} | - | " + " | ".join(pushes) + " |")
    return "\n".join(lines)


def keypoint_accuracy_table(
    accuracy: Mapping[str, Mapping[str, Sequence[float]]],
    models: Sequence[str],
    cameras: Sequence[str],
    registry: Mapping[str, Row] = ROWS,
) -> str:
    """Keypoint accuracy (%) of the keypoint models, ``accuracy[model][camera]`` per seed: the
    fraction of objects in view with a detected keypoint within the hit radius of their centre,
    on the row's test split (its training report), mean ± 95% interval over seeds."""
    lines = [
        "| model | " + " | ".join(f"{c} view (%)" for c in cameras) + " |",
        "|---|" + "---:|" * len(cameras),
    ]
    for model in models:
        if not any(accuracy.get(model, {}).get(c) for c in cameras):
            continue
        cells = []
        for camera in cameras:
            values = [100 * a for a in accuracy.get(model, {}).get(camera, [])]
            mean, half = mean_interval(values) if values else (None, None)
            cells.append(
                "-" if mean is None else f"{mean:.1f}" + ("" if half is None else f" ± {half:.1f}")
            )
        lines.append(f"| {label_of(model, registry)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def accuracy_section(
    accuracy: Mapping[str, Mapping[str, Sequence[float]]],
    models: Sequence[str],
    cameras: Sequence[str],
    registry: Mapping[str, Row],
) -> list[str]:
    """The keypoint-accuracy section of ``tables.md`` (none without keypoint rows)."""
    if not accuracy:
        return []
    return [
        "## Keypoint accuracy",
        "",
        "Objects in view with a detected keypoint within the hit radius of their centre, % of "
        "the row's test split (its training report), mean ± 95% interval over seeds:",
        "",
        keypoint_accuracy_table(accuracy, models, cameras, registry),
        "",
    ]


def generalization_sections(
    tables: TablesSettings,
    settings_of: Mapping[str, Any],
    mpc: Mapping[str, Mapping[str, Any]],
    cells: Mapping[str, Mapping[str, Any]],
) -> list[str]:
    """Table II and the backgrounds of ``tables.md`` (at the first budget, with its
    :class:`~kinet_rl.rearrangement.RearrangementSettings` in ``settings_of``), if any."""
    if not tables.mpc_budgets or not tables.generalization_models:
        return []
    first = next(iter(tables.mpc_budgets))
    settings, registry = settings_of[first], tables.rows
    models, sections = list(tables.generalization_models), []
    if settings.num_objects:
        sections += [
            f"## Table II: generalization (MPC final distance at the {first} budget, mm, mean "
            "± 95% interval)",
            "",
            table_ii(cells, models, settings.num_objects, settings.geometries, registry),
            "",
        ]
    if settings.backgrounds:
        sections += [
            f"## Backgrounds (MPC final distance at the {first} budget, mm, mean ± 95% interval)",
            "",
            background_table(mpc[first], cells, models, settings.backgrounds, registry),
            "",
        ]
    return sections


def _initial_distance(
    cells: Mapping[str, Mapping[str, SeedStats]], models: Sequence[str], cell: str
) -> str:
    for model in models:
        per_seed = cells.get(model, {}).get(cell)
        if per_seed:
            return f"{per_seed[0]['initial_distance'] * 1e3:.1f}"
    return "-"
