"""The comparison-tables command at smoke scale, and baseline MPC through the shared evaluation (slow)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from kinet_rl.envs import SceneSettings
from kinet_rl.pipeline import evaluate_rearrangement
from kinet_rl.rearrangement.settings import RearrangementSettings, TaskSettings
from kinet_rl.tables import TablesSettings, build_tables

pytestmark = pytest.mark.slow

SIZE = 32
PLANNER = {"planning_horizon": 1, "optim_steps": 2, "num_candidates": 16, "top_k": 4}


def smoke_overrides(root: Path) -> list[str]:
    """Smoke scale (as conf/exp/smoke.yaml) for every row, data under ``root``."""
    return [
        f"data.root={root / 'data'}",
        "data.name=tables_smoke_{camera}",
        f"env.image_size={SIZE}",
        "env.max_steps=5",
        "data.num_episodes=10",
        "data.num_workers=1",
        "data.chunk_episodes=2",
        "data.generalization=null",
        "trainer.steps=4",
        "trainer.batch_size=4",
        "trainer.log_every=2",
        "trainer.eval_every=4",
        "trainer.checkpoint_every=4",
        "trainer.val_batches=1",
        "report.horizons=[1]",
        "report.num_sequences=4",
        "report.rearrangement_episodes=0",
    ]


SMALL = ["model.hidden_dim=32", "model.num_hidden=1"]
SMALL_KINET = [*SMALL, "model.num_keypoints=4", "model.embed_dim=16"]


def test_tables_command_writes_every_row_with_finite_numbers(tmp_path: Path, conf_dir) -> None:
    torch.set_num_threads(1)
    models = [
        "kinet", "kinet_determ", "kinet_no_ctr", "forw", "forwinv", "in", "in_full", "visin", "vcdn"
    ]  # fmt: skip
    with initialize_config_dir(str(conf_dir), version_base="1.3"):
        overrides = [
            "tables.forward_sequences=8",
            "tables.forward_horizons=[1,3]",
            "tables.seeds=[0,1]",
        ]
        tables = compose(config_name="tables", overrides=overrides).tables
        OmegaConf.set_struct(tables, False)
        tiny_planner = {"planning_horizon": 1, "optim_steps": 1, "num_candidates": 8, "top_k": 2}
        tables.eval = {
            "episodes": 1,
            "num_steps": 2,
            "num_objects": [1, 3],
            "geometries": ["train", "gen"],
            "backgrounds": [],
            "generalization_episodes": 1,
            "workers": 1,
            "videos": 0,
            "planner": tiny_planner,
        }
        tables.mpc_budgets = {"8x1": {"num_candidates": 8, "optim_steps": 1, "top_k": 2},
                              "16x2": {"num_candidates": 16, "optim_steps": 2, "top_k": 4}}  # fmt: skip
        tables.overrides = smoke_overrides(tmp_path)
        tables.model_overrides = {
            m: SMALL_KINET if m.startswith("kinet") or m == "vcdn" else SMALL for m in models
        }
        tables = TablesSettings.from_container(OmegaConf.to_container(tables, resolve=True))
        path = build_tables(tables, tmp_path)
        text = path.read_text()
        # Resumable: a second call reuses every stage's JSON (no retraining).
        mtime = (tmp_path / "blocks_topview_in" / "results.json").stat().st_mtime
        assert build_tables(tables, tmp_path).read_text() == text
        assert (tmp_path / "blocks_topview_in" / "results.json").stat().st_mtime == mtime
    for label in ["KINet", "KINet-determ", "KINet-no-ctr", "Forw", "ForwInv", "IN (GT state)",
                  "IN-full (GT pos, yaw, shape)", "VisIN (GT state + image)", "V-CDN", "No motion", "Random pushes",
                  "Oracle MPC"]:  # fmt: skip
        assert f"| {label}" in text, label
    assert "not run" not in text
    table_i = text.split("## Table I")[1].split("Objects that moved")[0]
    rows_i = [line for line in table_i.splitlines() if line.startswith("| ") and "±" in line]
    # every model and the detector floor: mean ± 95% interval over the 2 seeds, both cameras;
    # no motion is the same for every seed (same test sequences), so it has no interval
    assert len(rows_i) == len(models) + 1 and all(line.count("±") == 2 for line in rows_i)
    assert "| Detector floor" in table_i and "| No motion" in table_i
    horizons = text.split("Moved objects after several open-loop pushes, top camera")[1]
    assert "| 3 pushes (mm) |" in horizons.split("## MPC")[0]
    sections = text.split("## MPC at the ")[1:]
    assert [s.split(" ")[0] for s in sections] == ["8x1", "16x2"]  # one table per budget
    for section, candidates in zip(sections, (8, 16), strict=True):
        mpc = section.split("## Table II")[0]
        assert f"Every row plans with {candidates} candidates" in mpc
        rows = [line for line in mpc.splitlines() if line.startswith("| ") and "±" in line]
        assert len(rows) == len(models) + 2
    table_ii = text.split("## Table II")[1]
    # KINet, KINet-determ and V-CDN (model_mpc at any object count) x 2 geometries, 2 counts
    assert len([line for line in table_ii.splitlines() if line.count("±") == 6]) == 2
    numbers = [float(x) for x in re.findall(r"(-?\d+\.\d+) ± (\d+\.\d+)", text) for x in x]
    assert numbers and all(torch.isfinite(torch.tensor(numbers)))
    assert (tmp_path / "mpc_curves_8x1.png").stat().st_size > 0
    for camera in ("top", "side"):
        assert (tmp_path / f"learning_curves_{camera}.png").stat().st_size > 0
        assert f"learning_curves_{camera}.png" in text
    for run in ("blocks_sideview_visin", "blocks_sideview_visin_seed1"):
        forward = json.loads((tmp_path / run / "tables_forward.json").read_text())
        assert set(forward) == {"1", "3"} and forward["1"]["no_motion"] > 0
    kinet = json.loads((tmp_path / "blocks_topview_seed1" / "tables_forward.json").read_text())
    assert kinet["1"]["floor"] > 0 and "floor_moved" in kinet["3"]
    assert not list((tmp_path / "blocks_topview_seed1").glob("tables_mpc*.json"))  # MPC: seed 0
    # Table II at the first budget only; an MPC result of other settings is not reused.
    larger = json.loads((tmp_path / "blocks_topview" / "tables_mpc_16x2.json").read_text())
    assert set(larger["value"]) == {"comparison"}
    assert larger["settings"]["rearrangement"]["planner"]["num_candidates"] == 16


@pytest.mark.parametrize(
    ("name", "workers"),
    [("forw", 1), ("forwinv", 1), ("in", 1), ("in_full", 2), ("visin", 2), ("vcdn", 2)],
)
def test_baseline_mpc_runs_through_the_shared_rearrangement_evaluation(
    name: str, workers: int, tmp_path: Path, tiny_baseline
) -> None:
    """An untrained baseline plans a short episode via ``evaluate_rearrangement`` (model_mpc)."""
    settings = RearrangementSettings(
        scene=SceneSettings(image_size=SIZE),
        task=TaskSettings(num_steps=3),
        episodes=workers,
        methods=("model_mpc",),
        planner=PLANNER,
        workers=workers,
        videos=0,
    )
    out = evaluate_rearrangement(tiny_baseline(name, image_size=SIZE), settings, tmp_path)
    stats = out["summary"]["comparison"]["model_mpc"]
    assert stats["episodes"] == workers and len(stats["mean_curve"]) == 4
    assert all(torch.isfinite(torch.tensor(stats["mean_curve"])))
    assert stats["initial_distance"] > 0.0
    assert (tmp_path / "rearrangement.md").is_file()
