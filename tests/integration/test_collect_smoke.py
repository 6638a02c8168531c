"""End-to-end ``python -m kinet_rl.collect +exp=smoke`` on the real MuJoCo env (slow)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from kinet_rl.data import load_dataset

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
MAIN_ONLY = ["data.generalization=null", "data.num_episodes=16"]


def collect_command(root: Path, *overrides: str) -> list[str]:
    return [sys.executable, "-m", "kinet_rl.collect", "+exp=smoke", f"data.root={root}", *overrides]


def run_collect(root: Path, *overrides: str) -> None:
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    result = subprocess.run(
        collect_command(root, *overrides),
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert result.returncode == 0, result.stderr[-3000:]


def stored(path: Path) -> TensorDict:
    return TensorDict.load_memmap(path / "episodes")


@pytest.fixture(scope="module")
def smoke_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("smoke")
    run_collect(root)
    return root


def test_smoke_collects_loadable_datasets(smoke_root: Path) -> None:
    expect = {"image_size": 32, "camera": "top", "task": "blocks"}
    data = load_dataset(smoke_root / "smoke", "train", expect=expect)
    batch = data.sample(32)
    assert batch["pixels"].shape == (32, 32, 32, 3) and batch["pixels"].dtype == torch.uint8
    assert batch["next", "object_pos"].shape == (32, 3, 2)
    moved = (batch["next", "object_pos"] - batch["object_pos"]).norm(dim=-1).amax(-1) > 1e-3
    assert moved.float().mean() > 0.3  # the object-targeting policy moves things
    two = load_dataset(smoke_root / "smoke_2obj", "all", expect={"num_objects": 2})
    assert two.sample_sequences(2, 5)["object_pos"].shape == (2, 6, 2, 2)


def test_rerun_of_a_complete_dataset_changes_nothing(smoke_root: Path) -> None:
    before = (smoke_root / "smoke" / "metadata.json").read_text()
    run_collect(smoke_root)
    assert (smoke_root / "smoke" / "metadata.json").read_text() == before


def test_killed_run_resumes_to_the_uninterrupted_dataset(tmp_path: Path) -> None:
    full, killed = tmp_path / "full", tmp_path / "killed"
    run_collect(full, *MAIN_ONLY)
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    process = subprocess.Popen(
        collect_command(killed, *MAIN_ONLY),
        cwd=REPO,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    progress = killed / "smoke" / "progress.json"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        if progress.exists() and json.loads(progress.read_text())["committed"] >= 2:
            process.send_signal(signal.SIGKILL)
            break
        time.sleep(0.01)
    process.wait(timeout=30)
    assert process.returncode == -signal.SIGKILL, "the run ended before it could be killed"
    assert not (killed / "smoke" / "metadata.json").exists()
    run_collect(killed, *MAIN_ONLY)
    assert (stored(killed / "smoke") == stored(full / "smoke")).all()


def test_two_workers_give_the_same_data(smoke_root: Path, tmp_path: Path) -> None:
    run_collect(tmp_path, "data.generalization=null", "data.num_workers=2")
    assert (stored(tmp_path / "smoke") == stored(smoke_root / "smoke")).all()
