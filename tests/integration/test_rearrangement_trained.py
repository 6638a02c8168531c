"""End to end: a KINet trained briefly in the simulator plans pushes that beat random ones (slow)."""

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


def test_trained_kinet_plans_closer_to_the_goal_than_random_pushes(tmp_path: Path) -> None:
    command = [
        sys.executable, "-m", "kinet_rl.train", "+exp=smoke", f"data.root={tmp_path / 'data'}",
        f"hydra.run.dir={tmp_path / 'run'}", "data.generalization=null", "data.num_episodes=40",
        "data.num_workers=2", "env.max_steps=20", "trainer.steps=400", "trainer.batch_size=32",
        "trainer.eval_every=400", "trainer.checkpoint_every=400", "trainer.log_every=100",
        "report.horizons=[1]", "report.num_sequences=64",
    ]  # fmt: skip
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    result = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-4000:]
    model = KINetWorldModel.from_checkpoint(tmp_path / "run" / "kinet.pt")
    eval_settings = {
        "episodes": 3,
        "methods": ["kinet_graph", "kinet_graph_distance", "kinet_keypoints", "random"],
        "num_steps": 10,
        "workers": 2,
        "videos": 0,
        "seed": 10000,
    }
    settings = RearrangementSettings.from_dicts(eval_settings, SCENE)
    summary = evaluate_rearrangement(model, settings, tmp_path / "eval")["summary"]["comparison"]
    random_final = summary["random"]["final_distance"]
    for method in ("kinet_graph", "kinet_graph_distance", "kinet_keypoints"):
        assert summary[method]["final_distance"] < random_final, (method, summary)
