"""Comparison rows as Hydra sweep jobs (joblib and submitit local launchers), then the tables.

Two experiments (IN, Forw) x two training seeds of ``ci/user_conf/tables/sweep_smoke.yaml`` run
as four jobs that share one dataset (the first collects it, the others wait for its lock); the
references (random pushes, the oracle) are a fifth job; ``aggregate=true`` then writes the tables
from the finished rows and lists what is missing without running it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
CONF = ("--config-dir", str(REPO / "ci" / "user_conf"))


def tables(cwd: Path, *overrides: str, multirun: bool = False) -> subprocess.CompletedProcess:
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "OMP_NUM_THREADS": "1"}
    flags = [*CONF, *(["-m"] if multirun else [])]
    command = [sys.executable, "-m", "kinet_rl.tables", *flags, "tables=sweep_smoke", *overrides]
    return subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=900)


@pytest.mark.parametrize("launcher", ["cores", "local"])
def test_a_sweep_of_two_experiments_and_two_seeds_then_the_tables(launcher, tmp_path) -> None:
    out = tmp_path / "runs" / "tables_sweep_smoke"
    before = tables(tmp_path, "aggregate=true")
    assert before.returncode == 0, before.stderr[-3000:]
    assert not list(out.glob("blocks_topview*")), "aggregate ran a row"
    missing = json.loads((out / "tables.json").read_text())["missing"]
    assert len(missing) == 5  # 4 rows and the references, none run
    jobs = ["row=in,forw", "seed=0,1", f"hydra/launcher={launcher}"]
    sweep = tables(tmp_path, *jobs, multirun=True)
    assert sweep.returncode == 0, sweep.stderr[-3000:]
    references = tables(tmp_path, "row=references", f"hydra/launcher={launcher}", multirun=True)
    assert references.returncode == 0, references.stderr[-3000:]
    after = tables(tmp_path, "aggregate=true")
    assert after.returncode == 0, after.stderr[-3000:]
    result = json.loads((out / "tables.json").read_text())
    assert result["missing"] == []
    assert {model: len(cams["top"]) for model, cams in result["forward"].items()} == {
        "in": 2,
        "forw": 2,
    }  # the four rows: two experiments x two seeds
    assert set(result["mpc"]["8x1"]) == {"in", "forw", "random", "oracle"}
    text = (out / "tables.md").read_text()
    assert "| IN (GT state) |" in text and "| Forw |" in text and "Not yet run" not in text
    # The four jobs shared one dataset, collected once.
    assert len(list((tmp_path / "data").iterdir())) == 1
    rerun = tables(tmp_path, *jobs, multirun=True)  # finished jobs resume: nothing trains again
    assert rerun.returncode == 0 and "Training blocks_topview" not in rerun.stderr
