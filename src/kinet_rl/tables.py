"""Train and evaluate every row of the comparison tables: ``python -m kinet_rl.tables [tables=paper]``.

For each row (a model of :data:`~kinet_rl.rows.ROWS`, or a variant of one: ``tables.variants``)
and camera, the row's config is the root config composed with the experiment
``+exp=<task>_<camera>view<suffix>`` (task ``blocks`` or ``ycb``) and the overrides of
``conf/tables/<scale>.yaml`` (:func:`row_config`); the row is trained with
:func:`kinet_rl.pipeline.run_experiment` in ``<out>/<exp_name>`` and then evaluated the same way
as every other row:

* Table I: single-step forward error on held-out test sequences (same sequences per camera), and
  the keypoint accuracy of its training report.
* MPC tables (``mpc_camera`` only), one per entry of ``mpc_budgets`` (every row of a table plans
  with the same budget, on the same episodes; an entry may name its rows and episodes):
  :func:`~kinet_rl.pipeline.evaluate_rearrangement` with the eval group's ``kinet_method``
  (KINet variants) or ``model_mpc`` (baselines), for the training seeds of ``mpc_seeds``, plus
  random pushes and the oracle.
* Table II and the backgrounds: the generalization cells (1-5 objects x train/gen geometry,
  extra backgrounds) of ``generalization_models``, at the first budget.

Every stage writes its JSON next to the row's run; re-running skips finished stages (a row's
training is finished when its ``results.json`` exists; an MPC result is redone when its
evaluation settings changed). Writes ``<out>/tables.md`` and ``<out>/mpc_curves_<budget>.png``.
The settings and the markdown are :mod:`kinet_rl.comparison`'s.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import hydra
import torch
from hydra import compose
from hydra.utils import get_class, instantiate
from omegaconf import DictConfig, OmegaConf

from kinet_rl.atomic import atomic_write_json, atomic_write_text, directory_lock
from kinet_rl.comparison import (
    CAMERAS,
    TASKS,
    TablesSettings,
    accuracy_section,
    generalization_sections,
    horizon_table,
    mpc_table,
    plot_learning_curves,
    plot_mpc_curves,
    table_i,
)
from kinet_rl.config_schema import (
    ConfigError,
    check_keys,
    config_group,
    require,
    settings_from,
)
from kinet_rl.configs import config_dir
from kinet_rl.data import load_dataset
from kinet_rl.envs.geometry import SceneGeometry
from kinet_rl.evaluation.forward import forward_errors
from kinet_rl.interrupts import exit_on_interrupt
from kinet_rl.models.checkpointing import ConfigCheckpointMixin
from kinet_rl.pipeline import (
    ExperimentSettings,
    check_config,
    check_dataset_for,
    evaluate_rearrangement,
    run_experiment,
)
from kinet_rl.planners.graph_mpc import check_planner_settings
from kinet_rl.rearrangement import RearrangementSettings
from kinet_rl.rearrangement.report import budget_text
from kinet_rl.rows import ROWS

logger = logging.getLogger(__name__)

#: The sweep job (``row=references``) of random pushes and the oracle on the MPC episodes.
REFERENCES = "references"
#: Keys of the root config besides the ``tables`` group (``conf/tables.yaml``).
ROOT_KEYS = ("tables", "row", "seed", "aggregate", "threads", "out_dir")


@dataclass(frozen=True)
class SweepJob:
    """What one invocation does (``conf/tables.yaml``): one ``row`` and ``seed`` of a sweep, or
    with no row every row and then the tables (``aggregate``: the tables from finished rows only).

    Raises:
        ConfigError: A row or seed that the scale does not have, named.
    """

    row: str | None = None
    seed: int | None = None
    aggregate: bool = False
    threads: int | None = None

    def check(self, tables: TablesSettings) -> None:
        """Raises ``ConfigError`` unless the row and seed are the scale's."""
        rows = [*tables.models, REFERENCES]
        require(self.row is None or self.row in rows, "row", self.row, f"one of {rows}")
        seeds = list(tables.seeds)
        require(self.seed is None or self.seed in seeds, "seed", self.seed, f"one of {seeds}")
        require(
            self.row is None or not self.aggregate,
            "aggregate",
            self.aggregate,
            "false for a sweep job (row=...); aggregate after the sweep, without row",
        )
        require(self.threads is None or self.threads >= 1, "threads", self.threads, "at least 1")


def experiment_name(model: str, camera: str, task: str = "blocks") -> str:
    """The experiment of a table row, e.g. ``blocks_topview_determ``."""
    if model not in ROWS or camera not in CAMERAS or task not in TASKS:
        raise ValueError(
            f"Unknown row ({task!r}, {model!r}, {camera!r}); tasks: {list(TASKS)}, models: "
            f"{sorted(ROWS)}, cameras: {list(CAMERAS)}. Fix conf/tables/<scale>.yaml."
        )
    return f"{task}_{camera}view{ROWS[model].experiment_suffix}"


def row_name(tables: TablesSettings, model: str, camera: str) -> str:
    """A row's run name (its ``exp_name``): its experiment's, ``_<name>`` added for a variant."""
    experiment = experiment_name(tables.base_model(model), camera, tables.task)
    return f"{experiment}_{model}" if model in tables.variants else experiment


def row_config(
    tables: TablesSettings, model: str, camera: str, seed: int = 0, training: bool = True
) -> DictConfig:
    """The composed training config of a row and training seed (needs an initialised Hydra).

    Its overrides, in order: ``overrides`` (``{camera}`` filled in), ``camera_overrides``, the
    model's ``model_overrides``, a variant's ``overrides`` and ``train_overrides`` and its
    ``exp_name``, then the seed. ``training=False`` leaves out ``train_overrides``: the config
    of the row's MPC episodes.
    """
    base = tables.base_model(model)
    exp, name = experiment_name(base, camera, tables.task), row_name(tables, model, camera)
    extra = [o.replace("{camera}", camera) for o in tables.overrides]
    extra += list(tables.camera_overrides.get(camera, []))
    extra += list(tables.model_overrides.get(base, []))
    variant = tables.variants.get(model)
    if variant is not None:
        extra += [*variant.overrides, *(variant.train_overrides if training else ())]
        extra.append(f"exp_name={name}")
    extra += [f"seed={seed}", f"trainer.seed={seed}"]
    cfg = compose(config_name="config", overrides=[f"+exp={exp}", *extra])
    if cfg.exp_name != name:
        raise ValueError(f"Experiment {exp} sets exp_name={cfg.exp_name}; the tables need {name}.")
    return cfg


def mpc_config(
    tables: TablesSettings, model: str, camera: str, seed: int, cfg: DictConfig
) -> DictConfig:
    """The config of a row's MPC episodes: its training config ``cfg``, or for a variant with
    ``train_overrides`` the config without them (the table's scene)."""
    variant = tables.variants.get(model)
    if variant is None or not variant.train_overrides:
        return cfg
    return row_config(tables, model, camera, seed, training=False)


def check_rows(
    tables: TablesSettings, models: Sequence[str] | None = None, seed: int | None = None
) -> None:
    """Composes and checks the config of every row (or of ``models``, with training seed
    ``seed``; default the first): :func:`~kinet_rl.pipeline.check_config`, its evaluation with
    the scale's ``eval`` overrides, and its planner under each of ``mpc_budgets``, before any
    row trains.

    Raises:
        ConfigError: The first invalid entry, naming the row it was found in.
    """
    seed = tables.seeds[0] if seed is None else seed
    for model in tables.models if models is None else models:
        for camera in tables.cameras:
            cfg = row_config(tables, model, camera, seed)
            try:
                check_config(to_dict(cfg))
                eval_cfg = mpc_config(tables, model, camera, seed, cfg)
                if eval_cfg is not cfg:
                    check_config(to_dict(eval_cfg))
                with config_group("tables.eval"):  # the row's eval group, with these overrides
                    planner = rearrangement_settings(eval_cfg, tables.eval).planner
                for name in tables.mpc_budgets:
                    with config_group(f"tables.mpc_budgets.{name}"):
                        check_planner_settings({**planner, **tables.budget_planner(name)})
            except ConfigError as err:
                raise ConfigError(
                    err.key,
                    f"{err.problem} (in row {cfg.exp_name}: "
                    f"+exp={experiment_name(tables.base_model(model), camera, tables.task)} "
                    f"with the overrides and eval entries of conf/tables/{tables.scale}.yaml)",
                ) from None


def load_model(cfg: DictConfig, run_dir: Path) -> Any:
    """The trained model of a row: ``kinet.pt`` (KINet) or ``model.pt`` (baselines)."""
    model_class = cast(type[ConfigCheckpointMixin], get_class(cfg.model._target_))
    model: Any = model_class.from_checkpoint(run_dir / model_class.model_file)
    return model.cpu().eval()


class NotRun(Exception):
    """A stage of a row (or the references) has not run: with ``run=False`` it is not run here."""


def _cached(
    path: Path, compute, settings: Mapping[str, Any] | None = None, run: bool = True
) -> Any:
    """The JSON at ``path``, computed and written first if missing (always read back: str keys).

    With ``settings`` the file also stores them, and is recomputed when they changed (e.g. an
    MPC result of another protocol or budget is not reused). With ``run=False`` a missing or
    outdated file raises :class:`NotRun` instead of being computed.
    """
    if settings is None:
        if not path.is_file():
            if not run:
                raise NotRun(path)
            atomic_write_json(path, compute())
        return json.loads(path.read_text())
    settings = json.loads(json.dumps(settings))  # the form it is read back in
    stored = json.loads(path.read_text()) if path.is_file() else {}
    if stored.get("settings") != settings:
        if not run:
            raise NotRun(path)
        if stored:
            logger.info("Recomputing %s: its evaluation settings changed", path)
        stored = {"settings": settings, "value": compute()}
        atomic_write_json(path, stored)
    return json.loads(json.dumps(stored["value"]))


def to_dict(node: DictConfig) -> dict[str, Any]:
    """A config node as a resolved plain dict."""
    return cast(dict[str, Any], OmegaConf.to_container(node, resolve=True))


def rearrangement_settings(
    cfg: DictConfig,
    eval_overrides: Mapping[str, Any],
    methods: list[str] | None = None,
    budget: str | None = None,
    tables: TablesSettings | None = None,
) -> RearrangementSettings:
    """The row's eval group with the table scale's overrides, and if given these methods and the
    MPC table ``budget`` of ``tables`` (its planner merged onto the eval group's, its episodes)."""
    container = to_dict(cfg)
    eval_cfg = {**container["eval"], **eval_overrides}
    if methods is not None:
        eval_cfg["methods"] = methods
    if budget is not None and tables is not None:
        eval_cfg["planner"] = {**eval_cfg["planner"], **tables.budget_planner(budget)}
        episodes = tables.mpc_budgets[budget].get("episodes")
        if episodes is not None:
            eval_cfg["episodes"] = episodes
    return RearrangementSettings.from_dicts(eval_cfg, container["env"])


def run_dir_of(out_dir: Path, exp_name: str, seed: int) -> Path:
    """A row's run directory: ``<out>/<exp_name>`` for seed 0, ``<out>/<exp_name>_seed<s>`` else."""
    return out_dir / (exp_name if seed == 0 else f"{exp_name}_seed{seed}")


def run_row(
    tables: TablesSettings,
    model: str,
    camera: str,
    out_dir: Path,
    seed: int = 0,
    run: bool = True,
) -> dict[str, Any]:
    """Trains (unless finished) and evaluates one row and seed; returns its table entries:
    ``forward`` (Table I), ``keypoint_accuracy`` (keypoint models; None for the others) and
    ``mpc`` (per MPC table: the row's stats per condition).

    Forward errors use the same test sequences (seed 0) for every row and training seed; the MPC
    evaluation runs for the training seeds of ``tables.planning_seeds``, at every budget that
    lists the row. With ``run=False`` nothing is trained or evaluated: a stage that has not run
    raises :class:`NotRun`.
    """
    cfg = row_config(tables, model, camera, seed)
    run_dir = run_dir_of(out_dir, cfg.exp_name, seed)
    if not (run_dir / "results.json").is_file():
        if not run:
            raise NotRun(run_dir)
        start = time.monotonic()
        logger.info("Training %s in %s", cfg.exp_name, run_dir)
        run_experiment(
            ExperimentSettings.from_container(to_dict(cfg)),
            lambda: instantiate(cfg.model, _convert_="all"),
            lambda model: instantiate(cfg.loss, world_model=model, _convert_="all"),
            run_dir,
        )
        logger.info("Trained %s in %.0f s", cfg.exp_name, time.monotonic() - start)
    net = load_model(cfg, run_dir)
    eval_overrides = tables.eval

    def forward() -> dict[int, dict[str, float]]:
        settings = ExperimentSettings.from_container(to_dict(cfg))
        test = load_dataset(settings.dataset_path, "test", settings.dataset_expect)
        check_dataset_for(net, test)
        scene = settings.scene
        geometry = SceneGeometry.of_scene(scene.task, scene.camera, scene.image_size)
        floor = net.detector_floor(geometry) if tables.rows[model].floor else None
        return forward_errors(
            net.object_rollout(geometry),
            test,
            tuple(tables.forward_horizons),
            tables.forward_sequences,
            seed=0,
            floor=floor,
        )

    forward_errors_of_row = _cached(run_dir / "tables_forward.json", forward, run=run)
    accuracy = json.loads((run_dir / "results.json").read_text()).get("keypoint_accuracy")
    row: dict[str, Any] = {
        "forward": forward_errors_of_row,
        "keypoint_accuracy": accuracy,
        "mpc": {},
    }
    if camera != tables.mpc_camera or seed not in tables.planning_seeds:
        return row
    eval_cfg = mpc_config(tables, model, camera, seed, cfg)
    kinet_method = rearrangement_settings(eval_cfg, eval_overrides).kinet_method
    method = tables.rows[model].method or kinet_method
    for i, budget in enumerate(tables.mpc_budgets):
        if model not in tables.budget_models(budget):
            continue
        # Table II and the backgrounds run at the first budget only.
        generalization = i == 0 and model in tables.generalization_models
        settings = rearrangement_settings(eval_cfg, eval_overrides, [method], budget, tables)

        def mpc(settings=settings, generalization=generalization, budget=budget) -> dict[str, Any]:
            start = time.monotonic()
            summary = evaluate_rearrangement(
                net, settings, run_dir / f"tables_mpc_{budget}", generalization, progress=True
            )["summary"]
            logger.info(
                "MPC of %s at %s took %.0f s", cfg.exp_name, budget, time.monotonic() - start
            )
            stats = {cond: by_method[method] for cond, by_method in summary.items()}
            # random pushes on each background's episodes (Fig. 4b): cond/random
            for cond, by_method in summary.items():
                if cond.startswith("background_") and "random" in by_method:
                    stats[f"{cond}/random"] = by_method["random"]
            return stats

        key = {"rearrangement": settings.as_dict(), "generalization": generalization}
        row["mpc"][budget] = _cached(run_dir / f"tables_mpc_{budget}.json", mpc, key, run)
    return row


def reference_settings(tables: TablesSettings, budget: str) -> RearrangementSettings:
    """The rearrangement settings of random pushes and the oracle at ``budget``: the episodes
    of its first row of the registry (its first row if all are variants)."""
    planned = tables.budget_models(budget)
    model = next((m for m in planned if m not in tables.variants), planned[0])
    cfg = row_config(tables, model, tables.mpc_camera)
    cfg = mpc_config(tables, model, tables.mpc_camera, 0, cfg)
    return rearrangement_settings(cfg, tables.eval, ["random", "oracle"], budget, tables)


def references(
    tables: TablesSettings, out_dir: Path, budget: str, run: bool = True
) -> tuple[dict[str, Any], RearrangementSettings]:
    """Random pushes and the oracle on the MPC table's episodes at ``budget``, and the settings
    (with ``run=False``, :class:`NotRun` if they have not run)."""
    settings = reference_settings(tables, budget)

    def compute() -> dict[str, Any]:
        summary = evaluate_rearrangement(
            None, settings, out_dir / f"references_{budget}", progress=True
        )
        return summary["summary"]["comparison"]

    stats = _cached(out_dir / f"references_{budget}.json", compute, settings.as_dict(), run)
    return stats, settings


def build_tables(tables: TablesSettings, out_dir: Path, run: bool = True) -> Path:
    """Checks every row's config, then (holding ``out_dir``'s lock) runs every row (resuming) and
    writes ``tables.md``, ``tables.json`` and one ``mpc_curves_<budget>.png`` per planner budget;
    returns the markdown path (needs an initialised Hydra). With ``run=False`` (after a sweep)
    nothing runs: the tables hold the finished rows and list the ones still missing.

    Raises:
        ConfigError: A row's config is invalid (nothing is written).
        DirectoryInUseError: Another process is building tables in ``out_dir``.
    """
    check_rows(tables)
    with directory_lock(out_dir, "building the comparison tables"):
        return _build_tables(tables, out_dir, run)


def run_job(tables: TablesSettings, job: SweepJob, out_dir: Path) -> None:
    """One job of a sweep: a row (every camera; ``job.seed`` or every seed) or the references,
    each resuming what it finished before (needs an initialised Hydra)."""
    if job.row is None:
        raise ValueError("A sweep job names its row (row=<model> or row=references).")
    if job.threads is not None:
        torch.set_num_threads(job.threads)
    seeds = tables.seeds if job.seed is None else (job.seed,)
    if job.row == REFERENCES:
        for budget in tables.mpc_budgets:
            references(tables, out_dir, budget)
        return
    check_rows(tables, [job.row], seeds[0])
    for seed in seeds:
        for camera in tables.cameras:
            logger.info("Sweep job: %s, %s view, seed %d", job.row, camera, seed)
            run_row(tables, job.row, camera, out_dir, seed)


def _build_tables(tables: TablesSettings, out_dir: Path, run: bool = True) -> Path:
    registry, models, cameras = tables.rows, list(tables.models), list(tables.cameras)
    forward: dict[str, dict[str, list[Any]]] = {}
    accuracy: dict[str, dict[str, list[float]]] = {}
    run_dirs: dict[str, dict[str, list[Path]]] = {}
    budgets = list(tables.mpc_budgets)
    mpc: dict[str, dict[str, list[Any]]] = {budget: {} for budget in budgets}
    cells: dict[str, dict[str, list[Any]]] = {}
    seeds = list(tables.seeds)
    rows = [(m, c, s) for s in seeds for c in cameras for m in models]
    missing: list[str] = []
    for i, (model, camera, seed) in enumerate(rows, start=1):
        logger.info("Row %d/%d: %s, %s view, seed %d", i, len(rows), model, camera, seed)
        try:
            row = run_row(tables, model, camera, out_dir, seed, run)
        except NotRun:
            missing.append(f"row={model} seed={seed} ({camera} camera)")
            continue
        forward.setdefault(model, {}).setdefault(camera, []).append(row["forward"])
        if row["keypoint_accuracy"] is not None:
            accuracy.setdefault(model, {}).setdefault(camera, []).append(row["keypoint_accuracy"])
        run_dirs.setdefault(camera, {}).setdefault(registry[model].label, []).append(
            run_dir_of(out_dir, row_name(tables, model, camera), seed)
        )
        for budget, by_condition in row["mpc"].items():  # seeds in order: lists per seed
            mpc[budget].setdefault(model, []).append(by_condition["comparison"])
            if budget == budgets[0]:
                for cond, stats in by_condition.items():
                    if cond != "comparison":
                        cells.setdefault(model, {}).setdefault(cond, []).append(stats)
    mpc_sections, settings_of = [], {}
    for budget in budgets:
        try:
            reference_stats, settings = references(tables, out_dir, budget, run)
        except NotRun:
            missing.append(f"row={REFERENCES} (random pushes and the oracle at {budget})")
            reference_stats, settings = {}, reference_settings(tables, budget)
        settings_of[budget] = settings
        mpc[budget].update({name: [stats] for name, stats in reference_stats.items()})
        plot = plot_mpc_curves(mpc[budget], out_dir / f"mpc_curves_{budget}.png", registry)
        planned = [f"seed {s}" for s in tables.planning_seeds]
        spread = (
            "mean ± 95% interval over episodes (Student's t); success: every object within the "
            "success threshold at T (95% Wilson interval)"
            if len(planned) == 1
            else f"mean ± 95% interval over the training seeds' means ({', '.join(planned)}; "
            "Student's t) and each seed's mean; success: every object within the success "
            "threshold at T, the mean rate over seeds"
        )
        mpc_sections += [
            f"## MPC at the {budget} budget: distance to goal after T pushes "
            f"({tables.mpc_camera} camera)",
            "",
            f"Ground-truth mean object distance to its goal position, mm, {spread}. Every row "
            f"plans with {budget_text(settings.planner)}, on {settings.episodes} "
            f"{settings.split} episodes.",
            "",
            mpc_table(
                mpc[budget],
                [*tables.budget_models(budget), "random", "oracle"],
                settings.task.num_steps,
                settings.kinet_method,
                registry,
            ),
            "",
            f"![distance to goal]({plot.name})",
            "",
        ]
    curves = [
        plot_learning_curves(runs, out_dir / f"learning_curves_{camera}.png", f"{camera} camera")
        for camera, runs in run_dirs.items()
    ]
    if budgets:
        settings = settings_of[budgets[0]]
        episodes = (
            f"rearrangement: {settings.split} episodes, seeds {settings.first_seed} + i (the "
            f"same episodes for every row; MPC with the models of seeds "
            f"{list(tables.planning_seeds)})"
        )
    else:
        episodes = "no MPC (mpc_budgets is empty)"
    text = "\n".join(
        [
            f"# KINet comparison tables ({tables.scale} scale)",
            "",
            f"Command: `python -m kinet_rl.tables tables={tables.scale}`; row configs: "
            f"`+exp={tables.task}_<camera>view<suffix>` with the overrides of "
            f"`conf/tables/{tables.scale}.yaml`; training seeds {seeds}, test sequences seed 0, "
            f"{episodes}.",
            "",
            f"## Table I: single-step forward error ({TASKS[tables.task]}, 3 objects)",
            "",
            "Mean object-position error on the table after one push, mm: the mean over the same "
            f"{tables.forward_sequences} held-out test sequences (start frame only, logged push) "
            f"for each training seed, then mean ± 95% interval over the {len(seeds)} seeds "
            "(Student's t; no interval for one seed).",
            "",
            table_i(forward, models, cameras, registry=registry),
            "",
            "Learning curves (1-push forward error on validation sequences, every seed): "
            + ", ".join(f"![{p.stem}]({p.name})" for p in curves),
            "",
            "Objects that moved in the push (more than 5 mm) only:",
            "",
            table_i(forward, models, cameras, subset="_moved", registry=registry),
            "",
            *[
                line
                for camera in cameras
                for line in (
                    f"Moved objects after several open-loop pushes, {camera} camera (mm, mean ± "
                    "95% interval over seeds):",
                    "",
                    horizon_table(forward, models, camera, list(tables.forward_horizons), registry),
                    "",
                )
            ],
            *accuracy_section(accuracy, models, cameras, registry),
            *mpc_sections,
            *generalization_sections(tables, settings_of, mpc, cells),
            *_missing_section(missing, tables.scale),
        ]
    )
    atomic_write_json(
        out_dir / "tables.json",
        {
            "forward": forward,
            "keypoint_accuracy": accuracy,
            "mpc": mpc,
            "generalization": cells,
            "missing": missing,
        },
    )
    path = out_dir / "tables.md"
    atomic_write_text(path, text)
    logger.info("Tables written to %s", path)
    if missing:
        logger.warning("Rows not yet run (%d): %s", len(missing), "; ".join(missing))
    return path


def _missing_section(missing: list[str], scale: str) -> list[str]:
    if not missing:
        return []
    return [
        "## Not yet run",
        "",
        "These rows have not finished; their cells are empty above. Run them, e.g. "
        f"`python -m kinet_rl.tables -m tables={scale} row=<model> seed=<seed>`:",
        "",
        *[f"* {row}" for row in missing],
        "",
    ]


@exit_on_interrupt("kinet_rl.tables")
@hydra.main(version_base="1.3", config_path=config_dir(), config_name="tables")
def main(cfg: DictConfig) -> None:
    """Entry point."""
    container = to_dict(cfg)
    check_keys(container, list(ROOT_KEYS))
    tables = TablesSettings.from_container(container["tables"])
    job = settings_from(
        SweepJob, {k: container[k] for k in ("row", "seed", "aggregate", "threads")}, ""
    )
    job.check(tables)
    out_dir = Path(container["out_dir"])
    if job.row is not None:
        run_job(tables, job, out_dir)
        return
    path = build_tables(tables, out_dir, run=not job.aggregate)
    print(path.read_text())


if __name__ == "__main__":
    # Run the importable module's main, not this __main__ copy's: a launcher (joblib, submitit)
    # pickles the job function, and functions and classes of __main__ do not unpickle in its jobs.
    from kinet_rl import tables

    tables.main()
