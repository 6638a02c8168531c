"""The tables of ``python -m kinet_rl.tables`` from finished rows, without training: variants,
MPC over several training seeds, per-budget rows and episodes, the backgrounds (Fig. 4b),
keypoint accuracy, and a config without MPC (Table I alone)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from kinet_rl import tables as tables_module
from kinet_rl.comparison import LABELS, mpc_table, table_ii
from kinet_rl.configs import config_dir
from kinet_rl.rearrangement.methods import METHODS
from kinet_rl.tables import TablesSettings, build_tables


def stats(final_mm: float, episodes: int = 20) -> dict[str, Any]:
    """Episode stats of one condition and method, as a rearrangement summary has them."""
    final = final_mm / 1e3
    return {
        "episodes": episodes,
        "initial_distance": 0.06,
        "final_distance": final,
        "final_distance_ci95": 0.004,
        "success_rate": 0.5,
        "success_ci95": [0.3, 0.7],
        "mean_curve": [0.06, final],
        "ci95_curve": [0.0, 0.004],
    }


def forward(error_mm: float) -> dict[str, dict[str, float]]:
    keys = ("model", "model_moved", "no_motion", "no_motion_moved", "floor", "floor_moved")
    return {str(h): {k: error_mm * h / 1e3 for k in keys} for h in (1, 5, 10)}


@pytest.fixture
def fake_rows(monkeypatch):
    """Every row and the references "finished": run_row answers from the row's name and seed
    (final distance 10 * seed + the row's index, in mm) and records what it was asked."""
    calls: list[tuple[str, str, int]] = []

    def run_row(tables, model, camera, out_dir, seed=0, run=True):
        calls.append((model, camera, seed))
        index = tables.models.index(model)
        row = {"forward": forward(10 + index), "mpc": {}}
        row["keypoint_accuracy"] = 0.9 if tables.rows[model].floor else None
        if camera == tables.mpc_camera and seed in tables.planning_seeds:
            for i, budget in enumerate(tables.mpc_budgets):
                if model in tables.budget_models(budget):
                    cells = {"comparison": stats(10 * seed + index)}
                    if i == 0 and model in tables.generalization_models:
                        cells |= {"n3_geom_train": stats(30 + seed), "background_random": stats(40)}
                        cells["background_random/random"] = stats(180)
                    row["mpc"][budget] = cells
        return row

    def references(tables, out_dir, budget, run=True):
        return {"random": stats(160), "oracle": stats(20)}, tables_module.reference_settings(
            tables, budget
        )

    monkeypatch.setattr(tables_module, "run_row", run_row)
    monkeypatch.setattr(tables_module, "references", references)
    monkeypatch.setattr(tables_module, "check_rows", lambda *args, **kwargs: None)
    monkeypatch.setattr(  # the fake rows have no training logs to draw
        tables_module, "plot_learning_curves", lambda runs, path, title: path
    )
    return calls


def tables_of(scale: str, *overrides: str) -> TablesSettings:
    cfg = compose(config_name="tables", overrides=[f"tables={scale}", *overrides])
    return TablesSettings.from_container(OmegaConf.to_container(cfg.tables, resolve=True))


def test_ycb_side_tables_plan_every_seed_and_name_the_variants(fake_rows, tmp_path: Path) -> None:
    with initialize_config_dir(config_dir(), version_base="1.3"):
        tables = tables_of("ycb_side96_cpu")
        text = build_tables(tables, tmp_path).read_text()
    result = json.loads((tmp_path / "tables.json").read_text())
    assert len(fake_rows) == len(tables.models) * 3  # every row, every seed, one camera
    # MPC for every training seed: the mean over seeds and each seed's final distance
    assert [s["final_distance"] for s in result["mpc"]["64x3"]["k3"]] == [0.009, 0.019, 0.029]
    assert f"| KINet, K = 3 | {METHODS['kinet_keypoints_distance'].label} |" in text
    assert "| 100 x 3 seeds |" not in text  # the fake stats have 20 episodes
    assert "| 20 x 3 seeds | 60.0 | 19.0 ± 24.8 (seeds: 9.0 / 19.0 / 29.0) | 50.0% (mean" in text
    assert result["mpc"]["64x3"]["random"][0]["final_distance"] == 0.16  # seed-free
    assert "| KINet, trained on 1-5 objects | " in text.split("## Table I")[1]
    # Table II (the object counts): KINet and the 1-5 model over seeds, 3 objects only here
    table2 = text.split("## Table II")[1]
    assert "KINet, trained on 1-5 objects train geom. (mm)" in table2
    assert "30.0 / 31.0 / 32.0" in table2
    assert "## Keypoint accuracy" in text and "| KINet, 128 px | 90.0 ± 0.0 |" in text
    assert "## Backgrounds" not in text


def test_fig4a_has_a_table_of_its_own_rows_and_episodes_per_budget(fake_rows, tmp_path) -> None:
    with initialize_config_dir(config_dir(), version_base="1.3"):
        tables = tables_of("fig4a_mpc_cpu")
        text = build_tables(tables, tmp_path).read_text()
        assert tables_module.reference_settings(tables, "64x3_1000ep").episodes == 1000
    sections = text.split("## MPC at the ")[1:]
    assert [s.split(" ")[0] for s in sections] == ["64x3", "256x5", "64x3_1000ep"]
    assert "on 100 test episodes" in sections[0] and "on 1000 test episodes" in sections[2]
    rows = [line.split(" | ")[0] for line in sections[2].splitlines() if line.startswith("| ")]
    labels = [f"| {LABELS[name]}" for name in ("kinet", "in", "random", "oracle")]
    assert rows[1:] == labels
    assert "## Table II" not in text


def test_fig4b_prints_each_model_on_both_backgrounds(fake_rows, tmp_path: Path) -> None:
    with initialize_config_dir(config_dir(), version_base="1.3"):
        text = build_tables(tables_of("fig4b_backgrounds_cpu"), tmp_path).read_text()
    backgrounds = text.split("## Backgrounds")[1]
    assert "| start | 60.0 | 60.0 |" in backgrounds
    assert "| KINet | 0.0 ± 4.0 (50% [30, 70]) | 40.0 ± 4.0 |" not in backgrounds
    assert "| KINet | 0.0 ± 4.0 | 40.0 ± 4.0 |" in backgrounds
    assert "| KINet, trained on random textures | 1.0 ± 4.0 | 40.0 ± 4.0 |" in backgrounds
    assert "| Random pushes | - | 180.0 ± 4.0 |" in backgrounds


def test_table_i_alone_runs_no_mpc(fake_rows, tmp_path: Path) -> None:
    with initialize_config_dir(config_dir(), version_base="1.3"):
        tables = tables_of("table1_cpu")
        assert tables.mpc_budgets == {}
        text = build_tables(tables, tmp_path).read_text()
    assert "## MPC" not in text and "## Table II" not in text and "no MPC" in text
    assert {camera for _, camera, _ in fake_rows} == {"top", "side"}
    assert "| VisIN (GT state + image) | 16.0 ± 0.0 | 16.0 ± 0.0 |" in text
    assert not list(tmp_path.glob("references*"))


def test_one_seed_keeps_the_interval_over_episodes() -> None:
    one = {"kinet": [stats(23.3, 100)]}
    line = mpc_table(one, ["kinet"], 40, "kinet_keypoints_l2").splitlines()[-1]
    planner = METHODS["kinet_keypoints_l2"].label
    assert line == f"| KINet | {planner} | 100 | 60.0 | 23.3 ± 4.0 | 50% [30, 70] |"
    cells = {"kinet": {"n1_geom_train": [stats(22.7)]}}
    assert "| 1 | 60.0 | 22.7 ± 4.0 |" in table_ii(cells, ["kinet"], [1], ["train"])
