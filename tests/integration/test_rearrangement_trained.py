"""End to end: GraphMPC with trained KINet models (slow).

* The shipped cpu-scale model brings the blocks at least 15 mm closer to their goals than they
  started, on validation episodes; a controller that does nothing fails this.
* A KINet trained briefly here (400 steps, 32 px) plans at least 10 mm closer to the goal than
  random pushes with the paper's (cosine) S; it is not yet good enough to end below the start
  (measured: 80.6 mm from 66.2 with the embedding distance, 4 episodes, T = 20), which is why the
  first test exists.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from kinet_rl.models import KINetWorldModel
from kinet_rl.pipeline import evaluate_rearrangement
from kinet_rl.rearrangement.settings import RearrangementSettings

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
SCENE = {"task": "blocks", "num_objects": 3, "camera": "top", "image_size": 32}


def test_shipped_kinet_graph_mpc_ends_closer_to_the_goal_than_it_started(tmp_path: Path) -> None:
    eval_settings = {
        "episodes": 4,
        "methods": ["kinet_graph_distance"],
        "num_steps": 40,
        "workers": 2,
        "videos": 0,
        "split": "validation",
    }
    scene = {**SCENE, "image_size": 64}
    settings = RearrangementSettings.from_dicts(eval_settings, scene)
    model = KINetWorldModel.from_pretrained("blocks_topview")
    summary = evaluate_rearrangement(model, settings, tmp_path)["summary"]["comparison"]
    stats = summary["kinet_graph_distance"]
    start, final = 1e3 * stats["initial_distance"], 1e3 * stats["final_distance"]
    assert final < start - 15.0, (start, final)


def test_trained_kinet_graph_mpc_plans_closer_to_the_goal_than_random_pushes(
    tmp_path: Path,
) -> None:
    command = [
        sys.executable, "-m", "kinet_rl.train", "+exp=smoke", f"data.root={tmp_path / 'data'}",
        f"hydra.run.dir={tmp_path / 'run'}", "data.generalization=null", "data.num_episodes=40",
        "data.num_workers=2", "env.max_steps=20", "trainer.steps=400", "trainer.batch_size=32",
        "trainer.eval_every=400", "trainer.checkpoint_every=400", "trainer.log_every=100",
        "report.horizons=[1]", "report.num_sequences=64",
    ]  # fmt: skip
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    result = subprocess.run(
        command, cwd=REPO, env=env, capture_output=True, text=True, timeout=1500
    )
    assert result.returncode == 0, result.stderr[-4000:]
    model = KINetWorldModel.from_checkpoint(tmp_path / "run" / "kinet.pt")
    eval_settings = {
        "episodes": 3,
        "methods": ["kinet_graph", "random"],
        "num_steps": 10,
        "workers": 2,
        "videos": 0,
        "split": "validation",
    }
    settings = RearrangementSettings.from_dicts(eval_settings, SCENE)
    summary = evaluate_rearrangement(model, settings, tmp_path / "eval")["summary"]["comparison"]
    finals = {method: round(1e3 * stats["final_distance"], 1) for method, stats in summary.items()}
    # Measured (seed 0, 3 episodes, start 61.6 mm), on two machines that train this model to
    # different floating-point results: GraphMPC with the cosine S 67.5 and 61.6 mm, random pushes
    # 91.6. Not asserted, because they swing with the machine: the embedding distance (73.3 on
    # the first machine, 137.5 on the second; 97.4 vs random 81.1 on 8 episodes there) and MPC on
    # keypoint positions (Chamfer 115.0 and 104.3; index-matched L2 113.5 on the second). After
    # 400 steps at 32 px only the cosine S plans reliably; the cpu-scale models plan with keypoint
    # L2 (docs/results.md), which the shipped-model test above checks.
    assert finals["kinet_graph"] < finals["random"] - 10.0, finals
