"""The published tables' configs (``conf/tables/*.yaml``) reproduce the runs of docs/results.md.

Before these configs, the rows of each table ran through queue scripts that called
``kinet_rl.train``, ``kinet_rl.evaluate`` or ``kinet_rl.tables`` with hard-coded overrides. Each
case here composes a row of a config (no training) and checks it against those commands: the
training config is the one the script's command composed (everything but the run's name), and
the MPC plans the same conditions (scene, episodes, planner, task, split) with the row's method
as the evaluation stored under ``docs/runs/`` (or, where none is stored, the script's settings).
"""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Any

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from kinet_rl.configs import config_dir
from kinet_rl.rearrangement import RearrangementSettings
from kinet_rl.tables import (
    TablesSettings,
    mpc_config,
    rearrangement_settings,
    row_config,
    row_name,
)

CONF = Path(config_dir())
RUNS = Path(__file__).resolve().parents[2] / "docs" / "runs"

#: The cpu scale's overrides of the BlockObjs scripts (conf/tables/cpu.yaml without data.name).
CPU = [
    "data.num_episodes=1250",
    "data.num_workers=2",
    "data.chunk_episodes=25",
    "data.generalization=null",
    "trainer.steps=10000",
    "trainer.batch_size=32",
    "trainer.eval_every=1000",
    "trainer.checkpoint_every=1000",
    "trainer.log_every=100",
    "report.rearrangement_episodes=0",
]
#: The default experiment's data and steps, as the default-scale script gave the baselines.
DEFAULT = [
    "data.name=blocks_top64",
    "data.num_episodes=100",
    "data.num_workers=2",
    "data.chunk_episodes=16",
    "data.generalization=null",
    "trainer.steps=1500",
    "trainer.batch_size=32",
    "trainer.log_every=25",
    "trainer.eval_every=250",
    "trainer.checkpoint_every=250",
    "report.rearrangement_episodes=0",
    "estimate=false",
]
#: What a YCB row script passed to train and evaluate (then exp_name, seed, trainer.seed).
YCB = ["+scale=cpu", "env.image_size=96"]
#: The evaluation of the BlockObjs MPC script (3 blocks, top camera, 64 px, T = 40, return_best).
SCRIPT_SCENE = {"task": "blocks", "num_objects": 3, "camera": "top", "image_size": 64}
SCRIPT_PLANNER = {
    "planning_horizon": 1, "optim_steps": 3, "num_candidates": 64, "top_k": 8,
    "update_rule": "cem", "temperature": 0.5, "min_std": 0.05, "max_std": 1.0, "return_best": True,
}  # fmt: skip
#: Keys of a composed config that name or time a run but change no result.
RUN_KEYS = ("exp_name", "estimate", "checkpoint")


@pytest.fixture(autouse=True)
def hydra_conf():
    with initialize_config_dir(str(CONF), version_base="1.3"):
        yield


@functools.cache
def tables_of(scale: str) -> TablesSettings:
    cfg = compose(config_name="tables", overrides=[f"tables={scale}"])
    return TablesSettings.from_container(OmegaConf.to_container(cfg.tables, resolve=True))


def result_keys(cfg: Any) -> dict[str, Any]:
    """A resolved config without the keys of :data:`RUN_KEYS`; ``data.generalization`` ``{}``
    (the default experiment's) as null: both are no held-out dataset
    (:func:`kinet_rl.pipeline.datasets.dataset_jobs`)."""
    out = {k: v for k, v in OmegaConf.to_container(cfg, resolve=True).items() if k not in RUN_KEYS}
    out["data"] = {**out["data"], "generalization": out["data"]["generalization"] or None}
    return out


def composed(*overrides: str) -> dict[str, Any]:
    """A command's resolved config (:func:`result_keys`)."""
    return result_keys(compose("config", overrides=list(overrides)))


def row(scale: str, model: str, camera: str, seed: int) -> dict[str, Any]:
    """A row's resolved training config (:func:`result_keys`)."""
    return result_keys(row_config(tables_of(scale), model, camera, seed))


def seeded(seed: int) -> list[str]:
    return [f"seed={seed}", f"trainer.seed={seed}"]


#: (config, row, camera, seed): the command that trained it (``"tables=cpu"``: that row of
#: ``tables=cpu``, which the table's rows ran as subsets of).
TRAINING = {
    "Table I, top": (("table1_cpu", "kinet", "top", 1), "tables=cpu"),
    "Table I, top ablation": (("table1_cpu", "kinet_no_ctr", "top", 2), "tables=cpu"),
    "Table I, side 96 px": (
        ("table1_cpu", "in_full", "side", 2),
        ["+exp=blocks_sideview_in_full", "data.name=tables_cpu_side96", "env.image_size=96"]
        + CPU
        + seeded(2),
    ),
    "Table I, side 96 px KINet-determ": (
        ("table1_cpu", "kinet_determ", "side", 0),
        ["+exp=blocks_sideview_determ", "data.name=tables_cpu_side96", "env.image_size=96"]
        + CPU
        + seeded(0),
    ),
    "Fig. 4a, KINet": (("fig4a_mpc_cpu", "kinet", "top", 0), "tables=cpu"),
    "Fig. 4a, IN of the 1,000 episodes": (
        ("fig4a_mpc_cpu", "in", "top", 0),
        ["+exp=blocks_topview_in", "+scale=cpu", "data.name=tables_cpu_top"],
    ),
    "Table II, KINet-determ": (("table2_cpu", "kinet_determ", "top", 0), "tables=cpu"),
    "Fig. 4b, cpu, random textures": (
        ("fig4b_backgrounds_cpu", "random_background", "top", 0),
        ["+exp=blocks_topview", *CPU, "estimate=false", "env.background=random"]
        + ["data.name=tables_cpu_top_random"],
    ),
    "Fig. 4b, default, fixed": (
        ("fig4b_backgrounds_default", "kinet", "top", 0),
        ["report.rearrangement_episodes=0", "estimate=false"],  # the default experiment
    ),
    "Fig. 4b, default, random textures": (
        ("fig4b_backgrounds_default", "random_background", "top", 0),
        ["report.rearrangement_episodes=0", "estimate=false", "env.background=random"]
        + ["data.name=blocks_top64_random"],
    ),
    "default MPC, KINet": (
        ("default_mpc", "kinet", "top", 0),
        ["report.rearrangement_episodes=0", "estimate=false"],
    ),
    "default MPC, ForwInv": (
        ("default_mpc", "forwinv", "top", 0),
        ["+exp=blocks_topview_forwinv"] + DEFAULT,
    ),
    "YCB side, KINet": (
        ("ycb_side96_cpu", "kinet", "side", 0),
        ["+exp=ycb_sideview", *YCB, "trainer.steps=8000"],
    ),
    "YCB side, V-CDN seed 2": (
        ("ycb_side96_cpu", "vcdn", "side", 2),
        ["+exp=ycb_sideview_vcdn", *YCB, *seeded(2), "trainer.steps=8000"],
    ),
    "YCB side, Forw seed 1": (
        ("ycb_side96_cpu", "forw", "side", 1),
        ["+exp=ycb_sideview_forw", *YCB, *seeded(1)],
    ),
    "Fig. 9b, K = 12": (
        ("ycb_side96_cpu", "k12", "side", 1),
        ["+exp=ycb_sideview", *YCB, "keypoints=12", *seeded(1), "trainer.steps=8000"],
    ),
    "Fig. 9c, 1-5 objects": (
        ("ycb_side96_cpu", "objects_1to5", "side", 2),
        ["+exp=ycb_sideview", *YCB, "data.num_objects_range=[1,5]"]
        + ["data.name=ycb_side96_1to5_cpu", "data.chunk_episodes=50", *seeded(2)]
        + ["trainer.steps=8000"],
    ),
    "YCB side, 128 px": (
        ("ycb_side96_cpu", "px128", "side", 0),
        ["+exp=ycb_sideview", "+scale=cpu", "env.image_size=128", "trainer.steps=8000"],
    ),
    "YCB top, KINet-no-ctr": (
        ("ycb_top96_cpu", "kinet_no_ctr", "top", 2),
        ["+exp=ycb_topview_no_ctr", *YCB, *seeded(2), "trainer.steps=8000"],
    ),
    "YCB top, IN-full": (
        ("ycb_top96_cpu", "in_full", "top", 1),
        ["+exp=ycb_topview_in_full", *YCB, *seeded(1)],
    ),
}


@pytest.mark.parametrize("case", list(TRAINING))
def test_each_row_trains_with_the_config_of_the_command_that_ran_it(case: str) -> None:
    (scale, model, camera, seed), command = TRAINING[case]
    expected = row("cpu", model, camera, seed) if command == "tables=cpu" else composed(*command)
    assert row(scale, model, camera, seed) == expected


def test_the_rows_keep_their_data_names_and_steps() -> None:
    """Spot checks of the values docs/results.md states (and the run folders the tables use)."""
    side = row("table1_cpu", "kinet", "side", 0)
    assert (side["env"]["image_size"], side["data"]["name"]) == (96, "tables_cpu_side96")
    assert row("table1_cpu", "kinet", "top", 0)["data"]["name"] == "tables_cpu_top"
    for model, steps, keypoints in (("kinet", 8000, 9), ("k3", 8000, 3), ("visin", 10000, None)):
        cfg = row("ycb_side96_cpu", model, "side", 0)
        assert (cfg["data"]["name"], cfg["trainer"]["steps"]) == ("ycb_side96_cpu", steps)
        assert cfg["model"].get("num_keypoints") == keypoints
    assert row("ycb_top96_cpu", "vcdn", "top", 0)["data"]["name"] == "ycb_top96_cpu"
    ycb = tables_of("ycb_side96_cpu")
    assert row_name(ycb, "k3", "side") == "ycb_sideview_k3"
    # Table I's test sequences: 1,024 per BlockObjs camera, 256 on YCBObjs; YCB plans every seed
    assert tables_of("table1_cpu").forward_sequences == 1024
    for scale in ("ycb_side96_cpu", "ycb_top96_cpu"):
        assert (tables_of(scale).forward_sequences, tables_of(scale).planning_seeds) == (
            256,
            (0, 1, 2),
        )
    assert row_name(tables_of("fig4b_backgrounds_cpu"), "random_background", "top") == (
        "blocks_topview_random_background"
    )  # the script's run name
    # The steps each training report stored (docs/runs) are the row's.
    for scale, model, camera, seed, results in (
        ("ycb_side96_cpu", "k3", "side", 0, "ycb_side96_cpu_fig9b/k3_seed0_results.json"),
        ("ycb_side96_cpu", "objects_1to5", "side", 1, "ycb_side96_cpu_fig9c/kinet_1to5_seed1_results.json"),
        ("ycb_side96_cpu", "forw", "side", 1, "ycb_side96_cpu_ablations/forw_seed1_results.json"),
        ("ycb_top96_cpu", "vcdn", "top", 2, "ycb_top96_cpu/vcdn_seed2_results.json"),
        ("table1_cpu", "in_full", "side", 2, "tables_cpu_side96/blocks_sideview_in_full_seed2/results.json"),
    ):  # fmt: skip
        stored = json.loads((RUNS / results).read_text())["step"]
        assert row(scale, model, camera, seed)["trainer"]["steps"] == stored, results


def stored_settings(path: str) -> RearrangementSettings:
    """The settings of an evaluation stored under docs/runs."""
    stored = json.loads((RUNS / path).read_text())["settings"]
    flat = {k: v for k, v in stored.items() if k not in ("scene", "task")}
    return RearrangementSettings.from_dicts({**flat, **stored["task"]}, stored["scene"])


def script_settings(episodes: int, methods: list[str], planner: dict) -> RearrangementSettings:
    """The settings of the BlockObjs MPC script (stored only as results, without settings)."""
    eval_cfg = {"episodes": episodes, "methods": methods, "num_steps": 40, "workers": 2}
    eval_cfg |= {"videos": 0, "split": "test", "planner": planner}
    return RearrangementSettings.from_dicts(eval_cfg, SCRIPT_SCENE)


def planned(
    scale: str, model: str, seed: int = 0, budget: str | None = None
) -> tuple[RearrangementSettings, bool, str]:
    """A row's MPC settings at ``budget`` (default: the first), whether its Table II cells and
    backgrounds run there, and its method."""
    tables = tables_of(scale)
    budget = budget or next(iter(tables.mpc_budgets))
    assert model in tables.budget_models(budget) and seed in tables.planning_seeds
    camera = tables.mpc_camera
    cfg = mpc_config(tables, model, camera, seed, row_config(tables, model, camera, seed))
    kinet_method = rearrangement_settings(cfg, tables.eval).kinet_method
    method = tables.rows[model].method or kinet_method
    settings = rearrangement_settings(cfg, tables.eval, [method], budget, tables)
    first = budget == next(iter(tables.mpc_budgets))
    return settings, first and model in tables.generalization_models, method


def assert_same_episodes(
    row: tuple[RearrangementSettings, bool, str],
    expected: RearrangementSettings,
    conditions: list[str] | None = None,
) -> None:
    """The row plans ``conditions`` (default: every condition ``expected`` ran) on the same
    scenes and episodes, with the same planner, task and split, with a method ``expected`` ran."""
    settings, generalization, method = row
    assert (settings.task, dict(settings.planner), settings.split) == (
        expected.task,
        dict(expected.planner),
        expected.split,
    )
    assert settings.oracle_contact_radius == expected.oracle_contact_radius
    mine = {c.name: c for c in settings.conditions(generalization)}
    theirs = {c.name: c for c in expected.conditions(True)}
    for name in theirs if conditions is None else conditions:
        assert name in mine, f"the row does not plan {name}"
        assert (mine[name].scene, mine[name].episodes) == (
            theirs[name].scene,
            theirs[name].episodes,
        )
        assert set(mine[name].methods) <= set(theirs[name].methods), name


def test_fig4a_plans_the_episodes_of_the_mpc_script_and_of_the_1000_episode_protocol() -> None:
    for model in ("kinet", "in", "forwinv", "forw"):
        method = "model_mpc" if model != "kinet" else "kinet_keypoints_l2"
        for budget, extra in (
            ("64x3", {}),
            ("256x5", {"num_candidates": 256, "optim_steps": 5, "top_k": 16}),
        ):
            expected = script_settings(100, [method], {**SCRIPT_PLANNER, **extra})
            assert_same_episodes(planned("fig4a_mpc_cpu", model, budget=budget), expected)
    assert_same_episodes(
        planned("fig4a_mpc_cpu", "kinet", budget="64x3_1000ep"),
        stored_settings("protocol1000/rearrangement.json"),
    )
    assert_same_episodes(
        planned("fig4a_mpc_cpu", "in", budget="64x3_1000ep"),
        stored_settings("protocol1000/in/rearrangement.json"),
    )
    assert tables_of("fig4a_mpc_cpu").budget_models("64x3_1000ep") == ["kinet", "in"]


#: (config, row, seed, stored evaluation, its conditions the row must plan; None: all).
STORED = {
    "Table II, KINet": ("table2_cpu", "kinet", 0, "table2_cpu/rearrangement.json", None),
    "Table II, KINet-determ": ("table2_cpu", "kinet_determ", 0, "table2_cpu_determ/rearrangement.json", None),
    "Fig. 4b cpu, random textures": (
        "fig4b_backgrounds_cpu", "random_background", 0, "background_cpu/rearrangement.json", None
    ),
    "Fig. 4b cpu, fixed background": (  # Table II's cells of the same scenes
        "fig4b_backgrounds_cpu", "kinet", 0, "table2_cpu/rearrangement.json", ["background_random"]
    ),
    "Fig. 4b default, random textures": (
        "fig4b_backgrounds_default", "random_background", 0, "default_rows/background/rearrangement.json", None
    ),
    "Fig. 4b default, fixed background": (
        "fig4b_backgrounds_default", "kinet", 0, "default_rows/table2/rearrangement.json", ["background_random"]
    ),
    "YCB side, KINet seed 0": (
        "ycb_side96_cpu", "kinet", 0, "ycb_cost_validation/test_side96_rearrangement.json", None
    ),
    "YCB side, KINet seed 0, object counts": (
        "ycb_side96_cpu", "kinet", 0, "ycb_side96_cpu_seeds/kinet_seed0_object_counts_rearrangement.json",
        [f"n{n}_geom_train" for n in range(1, 6)],
    ),
    "YCB side, KINet seed 1": ("ycb_side96_cpu", "kinet", 1, "ycb_side96_cpu_seeds/kinet_seed1_rearrangement.json", None),
    "YCB side, V-CDN": ("ycb_side96_cpu", "vcdn", 0, "ycb_side96_cpu_ablations/vcdn_rearrangement.json", None),
    "Fig. 9b, K = 3": ("ycb_side96_cpu", "k3", 0, "ycb_side96_cpu_fig9b/k3_seed0_rearrangement.json", None),
    "Fig. 9c, 1-5 objects": (
        "ycb_side96_cpu", "objects_1to5", 1, "ycb_side96_cpu_fig9c/kinet_1to5_seed1_rearrangement.json",
        [f"n{n}_geom_train" for n in range(1, 6)],
    ),
    "YCB top, KINet": ("ycb_top96_cpu", "kinet", 0, "ycb_top96_cpu/kinet_rearrangement.json", None),
    "YCB top, V-CDN seed 1": ("ycb_top96_cpu", "vcdn", 1, "ycb_top96_cpu/vcdn_seed1_rearrangement.json", None),
}  # fmt: skip


@pytest.mark.parametrize("case", list(STORED))
def test_each_row_plans_the_episodes_of_its_stored_evaluation(case: str) -> None:
    scale, model, seed, path, conditions = STORED[case]
    assert_same_episodes(planned(scale, model, seed), stored_settings(path), conditions)


def test_fig4b_plans_the_fixed_background_on_table_ii_scenes() -> None:
    """The table's scene of Fig. 4b (20 episodes) is Table II's 3-block training-geometry cell,
    for the fixed-background model and the one trained on random textures alike."""
    table2 = {c.name: c for c in stored_settings("table2_cpu/rearrangement.json").conditions()}
    for model in ("kinet", "random_background"):
        settings, _, method = planned("fig4b_backgrounds_cpu", model)
        (comparison,) = [c for c in settings.conditions(False)]
        assert (comparison.scene, comparison.episodes) == (
            table2["n3_geom_train"].scene,
            table2["n3_geom_train"].episodes,
        )
        assert settings.scene.background == "fixed" and method == "kinet_keypoints_l2"
    variant = row("fig4b_backgrounds_cpu", "random_background", "top", 0)
    assert variant["env"]["background"] == "random"  # trained on random textures


def test_every_published_config_names_its_commands_and_wall_time() -> None:
    for path in sorted((CONF / "tables").glob("*.yaml")):
        if path.stem in ("cpu", "cpu_ycb", "laptop", "paper"):  # the scales
            continue
        header = path.read_text().split("defaults:")[0]
        assert f"python -m kinet_rl.tables -m tables={path.stem} row=" in header, path.name
        assert f"python -m kinet_rl.tables tables={path.stem} aggregate=true" in header, path.name
        assert "Measured" in header, path.name
