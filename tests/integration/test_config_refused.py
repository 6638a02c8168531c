"""A bad override makes ``python -m kinet_rl.train`` fail in seconds, before any collection (slow:
a subprocess pays the imports)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
#: Seconds for Python, torch and Hydra to start and refuse; collecting the smoke data alone takes
#: longer, and a paper-scale dataset an hour.
STARTUP_BOUND_S = 60


def test_a_wrong_type_fails_before_the_dataset_is_collected(tmp_path: Path) -> None:
    data = tmp_path / "data"
    command = [
        sys.executable,
        "-m",
        "kinet_rl.train",
        "+exp=smoke",
        "trainer.steps=abc",
        f"data.root={data}",
        f"hydra.run.dir={tmp_path / 'run'}",
    ]
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "OMP_NUM_THREADS": "1"}
    start = time.monotonic()
    result = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    elapsed = time.monotonic() - start
    assert result.returncode != 0
    assert "Config entry trainer.steps: got 'abc', expected an integer." in result.stderr
    assert not data.exists()  # refused before collection started
    assert elapsed < STARTUP_BOUND_S, f"took {elapsed:.0f} s to refuse"
