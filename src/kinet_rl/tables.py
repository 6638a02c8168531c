"""Train and evaluate every row of the comparison tables: ``python -m kinet_rl.tables [tables=paper]``.

For each model (KINet, its ablations and the baselines) and camera, the row's config is the root
config composed with the experiment ``+exp=blocks_<camera>view<suffix>`` and the scale's
overrides (``conf/tables/<scale>.yaml``); the row is trained with
:func:`kinet_rl.pipeline.run_experiment` in ``<out>/<exp_name>`` and then evaluated the same way
as every other row:

* Table I: single-step forward error on held-out test sequences (same sequences per camera).
* MPC table (``mpc_camera`` only): :func:`~kinet_rl.pipeline.evaluate_rearrangement`
  with ``kinet_graph`` (KINet variants) or ``model_mpc`` (baselines), on the same episodes, plus
  random pushes and the oracle.
* Table II: the generalization cells (1-5 objects x train/gen geometry) of ``generalization_models``.

Every stage writes its JSON next to the row's run; re-running skips finished stages (a row's
training is finished when its ``results.json`` exists). Writes ``<out>/tables.md`` and
``<out>/mpc_curves.png``.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import hydra
from hydra import compose
from hydra.core.hydra_config import HydraConfig
from hydra.utils import get_class, instantiate
from omegaconf import DictConfig, OmegaConf

from kinet_rl.atomic import atomic_write_json, atomic_write_text
from kinet_rl.comparison import (
    LABELS,
    horizon_table,
    mpc_table,
    plot_learning_curves,
    plot_mpc_curves,
    table_i,
    table_ii,
)
from kinet_rl.config_schema import ConfigError, check_keys, config_group, require, settings_from
from kinet_rl.configs import config_dir
from kinet_rl.data import load_dataset
from kinet_rl.envs.geometry import SceneGeometry
from kinet_rl.evaluation.forward import forward_errors
from kinet_rl.models import KINetWorldModel
from kinet_rl.models.checkpointing import ConfigCheckpointMixin
from kinet_rl.pipeline import (
    BASELINE_FILE,
    DATASET_ENV_KEYS,
    KINET_FILE,
    ExperimentSettings,
    check_config,
    evaluate_rearrangement,
    run_experiment,
)
from kinet_rl.rearrangement import RearrangementSettings

logger = logging.getLogger(__name__)

#: Experiment-name suffix of each row model (``conf/exp/blocks_<camera>view<suffix>.yaml``).
EXPERIMENT_SUFFIX = {
    "kinet": "",
    "kinet_determ": "_determ",
    "kinet_no_ctr": "_no_ctr",
    "forw": "_forw",
    "forwinv": "_forwinv",
    "in": "_in",
    "visin": "_visin",
}
CAMERAS = ("top", "side")


@dataclass(frozen=True)
class TablesSettings:
    """The ``tables`` config group (``conf/tables/<scale>.yaml``; each file documents its keys).

    Raises:
        ConfigError: A model, camera or seed that no row can have, named.
    """

    scale: str
    models: tuple[str, ...]
    cameras: tuple[str, ...]
    mpc_camera: str
    generalization_models: tuple[str, ...]
    seeds: tuple[int, ...]
    forward_horizons: tuple[int, ...]
    forward_sequences: int
    overrides: tuple[str, ...] = ()
    model_overrides: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    eval: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name, choices, least in (
            ("models", tuple(EXPERIMENT_SUFFIX), 1),
            ("cameras", CAMERAS, 1),
            ("generalization_models", self.models, 0),
            ("model_overrides", tuple(EXPERIMENT_SUFFIX), 0),
        ):
            values = list(getattr(self, name))
            require(
                len(values) >= least and set(values) <= set(choices),
                name,
                values,
                f"{'a non-empty list' if least else 'a list'} of names from {list(choices)}",
            )
        require(self.mpc_camera in self.cameras, "mpc_camera", self.mpc_camera, "one of cameras")
        for name, low in (("seeds", 0), ("forward_horizons", 1)):
            values = list(getattr(self, name))
            require(
                bool(values) and min(values) >= low,
                name,
                values,
                f"a non-empty list of integers of at least {low}",
            )
        require(
            self.forward_sequences >= 1,
            "forward_sequences",
            self.forward_sequences,
            "an integer of at least 1",
        )

    @classmethod
    def from_container(cls, values: Mapping[str, Any]) -> TablesSettings:
        """Settings from the resolved ``tables`` group."""
        return settings_from(cls, values, "tables")


def experiment_name(model: str, camera: str) -> str:
    """The experiment of a table row, e.g. ``blocks_topview_determ``."""
    if model not in EXPERIMENT_SUFFIX or camera not in CAMERAS:
        raise ValueError(
            f"Unknown row ({model!r}, {camera!r}); models: {sorted(EXPERIMENT_SUFFIX)}, cameras: "
            f"{list(CAMERAS)}. Fix conf/tables/<scale>.yaml."
        )
    return f"blocks_{camera}view{EXPERIMENT_SUFFIX[model]}"


def row_config(tables: TablesSettings, model: str, camera: str, seed: int = 0) -> DictConfig:
    """The composed training config of a row and training seed (needs an initialised Hydra)."""
    exp = experiment_name(model, camera)
    extra = [o.replace("{camera}", camera) for o in tables.overrides]
    extra += list(tables.model_overrides.get(model, []))
    extra += [f"seed={seed}", f"trainer.seed={seed}"]
    cfg = compose(config_name="config", overrides=[f"+exp={exp}", *extra])
    if cfg.exp_name != exp:
        raise ValueError(
            f"Experiment {exp} sets exp_name={cfg.exp_name}; the tables need them equal."
        )
    return cfg


def check_rows(tables: TablesSettings) -> None:
    """Composes and checks the config of every row (:func:`~kinet_rl.pipeline.check_config`,
    and its evaluation with the scale's ``eval`` overrides) before any row trains.

    Raises:
        ConfigError: The first invalid entry, naming the row it was found in.
    """
    for model in tables.models:
        for camera in tables.cameras:
            cfg = row_config(tables, model, camera, tables.seeds[0])
            try:
                check_config(to_dict(cfg))
                with config_group("tables.eval"):  # the row's eval group, with these overrides
                    rearrangement_settings(cfg, tables.eval)
            except ConfigError as err:
                raise ConfigError(
                    err.key,
                    f"{err.problem} (in row {cfg.exp_name}: +exp={cfg.exp_name} with the "
                    f"overrides and eval entries of conf/tables/{tables.scale}.yaml)",
                ) from None


def load_model(cfg: DictConfig, run_dir: Path) -> Any:
    """The trained model of a row: ``kinet.pt`` (KINet) or ``model.pt`` (baselines)."""
    model_class = cast(type[ConfigCheckpointMixin], get_class(cfg.model._target_))
    name = KINET_FILE if issubclass(model_class, KINetWorldModel) else BASELINE_FILE
    model: Any = model_class.from_checkpoint(run_dir / name)
    return model.cpu().eval()


def _cached(path: Path, compute) -> Any:
    """The JSON at ``path``, computed and written first if missing (always read back: str keys)."""
    if not path.is_file():
        atomic_write_json(path, compute())
    return json.loads(path.read_text())


def to_dict(node: DictConfig) -> dict[str, Any]:
    """A config node as a resolved plain dict."""
    return cast(dict[str, Any], OmegaConf.to_container(node, resolve=True))


def rearrangement_settings(
    cfg: DictConfig, eval_overrides: Mapping[str, Any], methods: list[str] | None = None
) -> RearrangementSettings:
    """The row's eval group with the table scale's overrides and, if given, these methods."""
    container = to_dict(cfg)
    eval_cfg = {**container["eval"], **eval_overrides}
    if methods is not None:
        eval_cfg["methods"] = methods
    return RearrangementSettings.from_dicts(eval_cfg, container["env"])


def run_dir_of(out_dir: Path, exp_name: str, seed: int) -> Path:
    """A row's run directory: ``<out>/<exp_name>`` for seed 0, ``<out>/<exp_name>_seed<s>`` else."""
    return out_dir / (exp_name if seed == 0 else f"{exp_name}_seed{seed}")


def run_row(
    tables: TablesSettings, model: str, camera: str, out_dir: Path, seed: int = 0
) -> dict[str, Any]:
    """Trains (unless finished) and evaluates one row and seed; returns its table entries.

    Forward errors use the same test sequences (seed 0) for every row and training seed; the MPC
    evaluation runs for the first training seed only.
    """
    cfg = row_config(tables, model, camera, seed)
    run_dir = run_dir_of(out_dir, cfg.exp_name, seed)
    if not (run_dir / "results.json").is_file():
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

    def forward() -> dict[str, Any]:
        settings = ExperimentSettings.from_container(to_dict(cfg))
        expect = {k: settings.env[k] for k in DATASET_ENV_KEYS}
        test = load_dataset(settings.dataset_path, "test", expect)
        scene = settings.scene
        geometry = SceneGeometry.of_scene(scene.task, scene.camera, scene.image_size)
        floor = net.detector_floor(geometry) if isinstance(net, KINetWorldModel) else None
        return forward_errors(
            net.object_rollout(geometry),
            test,
            tuple(tables.forward_horizons),
            tables.forward_sequences,
            seed=0,
            floor=floor,
        )

    row: dict[str, Any] = {"forward": _cached(run_dir / "tables_forward.json", forward)}
    if camera == tables.mpc_camera and seed == tables.seeds[0]:
        kinet_method = rearrangement_settings(cfg, eval_overrides).kinet_method
        method = kinet_method if isinstance(net, KINetWorldModel) else "model_mpc"
        generalization = model in tables.generalization_models

        def mpc() -> dict[str, Any]:
            settings = rearrangement_settings(cfg, eval_overrides, [method])
            start = time.monotonic()
            summary = evaluate_rearrangement(
                net, settings, run_dir / "tables_mpc", generalization, progress=True
            )["summary"]
            logger.info("MPC evaluation of %s took %.0f s", cfg.exp_name, time.monotonic() - start)
            return {cond: by_method[method] for cond, by_method in summary.items()}

        row["mpc"] = _cached(run_dir / "tables_mpc.json", mpc)
    return row


def references(
    tables: TablesSettings, out_dir: Path
) -> tuple[dict[str, Any], RearrangementSettings]:
    """Random pushes and the oracle on the MPC table's episodes (no model), and the settings."""
    cfg = row_config(tables, tables.models[0], tables.mpc_camera)
    settings = rearrangement_settings(cfg, tables.eval, ["random", "oracle"])

    def compute() -> dict[str, Any]:
        summary = evaluate_rearrangement(None, settings, out_dir / "references", progress=True)
        return summary["summary"]["comparison"]

    return _cached(out_dir / "references.json", compute), settings


def build_tables(tables: TablesSettings, out_dir: Path) -> Path:
    """Checks every row's config, runs every row (resuming), then writes ``tables.md`` and
    ``mpc_curves.png``; returns the markdown path (needs an initialised Hydra)."""
    check_rows(tables)
    forward: dict[str, dict[str, list[Any]]] = {}
    run_dirs: dict[str, dict[str, list[Path]]] = {}
    mpc: dict[str, Any] = {}
    cells: dict[str, dict[str, Any]] = {}
    seeds = list(tables.seeds)
    rows = [(m, c, s) for s in seeds for c in tables.cameras for m in tables.models]
    for i, (model, camera, seed) in enumerate(rows, start=1):
        logger.info("Row %d/%d: %s, %s view, seed %d", i, len(rows), model, camera, seed)
        row = run_row(tables, model, camera, out_dir, seed)
        forward.setdefault(model, {}).setdefault(camera, []).append(row["forward"])
        run_dirs.setdefault(camera, {}).setdefault(LABELS.get(model, model), []).append(
            run_dir_of(out_dir, experiment_name(model, camera), seed)
        )
        if "mpc" in row:
            mpc[model] = row["mpc"]["comparison"]
            cells[model] = {k: v for k, v in row["mpc"].items() if k != "comparison"}
    reference_stats, settings = references(tables, out_dir)
    mpc.update(reference_stats)
    plot = plot_mpc_curves(mpc, out_dir / "mpc_curves.png")
    curves = [
        plot_learning_curves(runs, out_dir / f"learning_curves_{camera}.png", f"{camera} camera")
        for camera, runs in run_dirs.items()
    ]
    text = "\n".join(
        [
            f"# KINet comparison tables ({tables.scale} scale)",
            "",
            f"Command: `python -m kinet_rl.tables tables={tables.scale}`; row configs: "
            "`+exp=blocks_<camera>view<suffix>` with the overrides of "
            f"`conf/tables/{tables.scale}.yaml`; training seeds {seeds}, test sequences seed 0, "
            "rearrangement episodes seed 10000 + i (the same episodes for every row; MPC with the "
            f"models of seed {seeds[0]}).",
            "",
            "## Table I: single-step forward error (BlockObjs, 3 objects)",
            "",
            "Mean object-position error on the table after one push, mm: the mean over the same "
            f"{tables.forward_sequences} held-out test sequences (start frame only, logged push) "
            f"for each training seed, then mean ± 95% interval over the {len(seeds)} seeds "
            "(Student's t; no interval for one seed).",
            "",
            table_i(forward, list(tables.models), list(tables.cameras)),
            "",
            "Learning curves (1-push forward error on validation sequences, every seed): "
            + ", ".join(f"![{p.stem}]({p.name})" for p in curves),
            "",
            "Objects that moved in the push (more than 5 mm) only:",
            "",
            table_i(forward, list(tables.models), list(tables.cameras), subset="_moved"),
            "",
            *[
                line
                for camera in tables.cameras
                for line in (
                    f"Moved objects after several open-loop pushes, {camera} camera (mm, mean ± "
                    "95% interval over seeds):",
                    "",
                    horizon_table(
                        forward, list(tables.models), camera, list(tables.forward_horizons)
                    ),
                    "",
                )
            ],
            f"## MPC: distance to goal after T pushes ({tables.mpc_camera} camera)",
            "",
            "Ground-truth mean object distance to its goal position, mm, mean ± standard error over "
            "episodes; success: every object within the success threshold at T.",
            "",
            mpc_table(
                mpc,
                [*tables.models, "random", "oracle"],
                settings.task.num_steps,
                settings.kinet_method,
            ),
            "",
            f"![distance to goal]({plot.name})",
            "",
            "## Table II: generalization (MPC final distance, mm, mean ± s.e.)",
            "",
            table_ii(
                cells,
                list(tables.generalization_models),
                settings.num_objects,
                settings.geometries,
            ),
            "",
        ]
    )
    path = out_dir / "tables.md"
    atomic_write_text(path, text)
    logger.info("Tables written to %s", path)
    return path


@hydra.main(version_base="1.3", config_path=config_dir(), config_name="tables")
def main(cfg: DictConfig) -> None:
    """Entry point."""
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    container = to_dict(cfg)
    check_keys(container, ["tables"])
    path = build_tables(TablesSettings.from_container(container["tables"]), out_dir)
    print(path.read_text())


if __name__ == "__main__":
    main()
