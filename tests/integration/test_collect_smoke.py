"""End-to-end ``python -m kinet_rl.collect +exp=smoke`` on the real MuJoCo env (slow)."""

from __future__ import annotations

import json
import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from kinet_rl.atomic import DirectoryInUseError, directory_lock
from kinet_rl.data import load_dataset
from kinet_rl.data.object_counts import chunk_object_count

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
MAIN_ONLY = ["data.generalization=null", "data.num_episodes=16"]


def collect_command(root: Path, *overrides: str) -> list[str]:
    return [sys.executable, "-m", "kinet_rl.collect", "+exp=smoke", f"data.root={root}", *overrides]


def subprocess_env() -> dict[str, str]:
    return {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}


def run_collect(root: Path, *overrides: str, command: list[str] | None = None) -> None:
    result = subprocess.run(
        command or collect_command(root, *overrides),
        cwd=REPO,
        env=subprocess_env(),
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert result.returncode == 0, result.stderr[-3000:]


def committed(path: Path) -> int:
    """Episodes committed so far to the dataset at ``path`` (0 before the first record)."""
    progress = path / "progress.json"
    return json.loads(progress.read_text())["committed"] if progress.exists() else 0


def wait_for_commits(process: subprocess.Popen, dataset: Path, episodes: int) -> int:
    """Waits until ``process`` has committed ``episodes`` to ``dataset``; returns the count."""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        if committed(dataset) >= episodes:
            break
        time.sleep(0.01)
    return committed(dataset)


def live_processes(session: int) -> list[int]:
    """PIDs of the processes of a session that are still running (zombies are dead)."""
    pids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            state, _, _, sid = stat.read_text().rsplit(")", 1)[1].split()[:4]
        except (OSError, IndexError):
            continue  # the process ended while being read
        if int(sid) == session and state != "Z":
            pids.append(int(stat.parent.name))
    return pids


def stored(path: Path) -> TensorDict:
    return TensorDict.load_memmap(path / "episodes")


@pytest.fixture(scope="module")
def smoke_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("smoke")
    run_collect(root)
    return root


@pytest.fixture(scope="module")
def main_only_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An uninterrupted collection of the ``MAIN_ONLY`` dataset, one worker."""
    root = tmp_path_factory.mktemp("main_only")
    run_collect(root, *MAIN_ONLY)
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


def test_killed_run_resumes_to_the_uninterrupted_dataset(
    main_only_root: Path, tmp_path: Path
) -> None:
    killed = tmp_path / "killed"
    process = subprocess.Popen(
        collect_command(killed, *MAIN_ONLY),
        cwd=REPO,
        env=subprocess_env(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    if wait_for_commits(process, killed / "smoke", 2) >= 2:
        process.send_signal(signal.SIGKILL)
    process.wait(timeout=30)
    assert process.returncode == -signal.SIGKILL, "the run ended before it could be killed"
    assert not (killed / "smoke" / "metadata.json").exists()
    run_collect(killed, *MAIN_ONLY)  # the lock of the killed process does not block
    assert (stored(killed / "smoke") == stored(main_only_root / "smoke")).all()


def test_two_workers_give_the_same_data(smoke_root: Path, tmp_path: Path) -> None:
    run_collect(tmp_path, "data.generalization=null", "data.num_workers=2")
    assert (stored(tmp_path / "smoke") == stored(smoke_root / "smoke")).all()


def test_ctrl_c_stops_two_workers_promptly_and_the_printed_command_resumes(
    main_only_root: Path, tmp_path: Path
) -> None:
    interrupted = tmp_path / "interrupted"
    command = collect_command(interrupted, *MAIN_ONLY, "data.num_workers=2")
    with open(tmp_path / "stderr.txt", "w+") as stderr:
        process = subprocess.Popen(
            command,
            cwd=REPO,
            env=subprocess_env(),
            stdout=subprocess.DEVNULL,
            stderr=stderr,
            start_new_session=True,  # its own process group, as a terminal's job
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # pytest may ignore it
        )
        seen = wait_for_commits(process, interrupted / "smoke", 2)
        assert seen >= 2 and len(live_processes(process.pid)) >= 3, "no workers to interrupt"
        busy = pytest.raises(DirectoryInUseError, match=f"PID {process.pid}\\) is collecting")
        with busy, directory_lock(interrupted / "smoke", "collecting a dataset"):
            pass
        os.killpg(process.pid, signal.SIGINT)  # what Ctrl-C in a terminal does
        start = time.monotonic()
        process.wait(timeout=60)
        stopped_after = time.monotonic() - start
        stderr.seek(0)
        output = stderr.read()
    assert process.returncode == 130, output[-3000:]
    assert stopped_after < 15, f"took {stopped_after:.1f} s to stop"
    while live_processes(process.pid) and time.monotonic() < start + 20:
        time.sleep(0.1)  # the resource tracker ends once its pipe closes
    assert live_processes(process.pid) == [], "orphaned worker processes"
    assert "Traceback" not in output, output[-3000:]
    assert committed(interrupted / "smoke") >= seen
    assert not (interrupted / "smoke" / "metadata.json").exists(), "the run ended by itself"
    resume = shlex.split(output.strip().splitlines()[-1].split("run the same command again: ")[1])
    assert resume == ["python", *command[1:]]
    run_collect(interrupted, command=[sys.executable, *resume[1:]])
    assert (stored(interrupted / "smoke") == stored(main_only_root / "smoke")).all()


def test_a_count_range_collects_each_chunk_with_its_object_count(tmp_path: Path) -> None:
    run_collect(tmp_path / "range", "data.generalization=null", "data.num_objects_range=[1,3]")
    episodes = stored(tmp_path / "range" / "smoke")
    counts, source = episodes["num_objects"], episodes["source_episode"]
    assert set(counts.tolist()) == {1, 2, 3}  # seed 0's chunks of 2 draw 2, 3, 1, 2, 1, ...
    assert counts.tolist() == [chunk_object_count(0, s // 2, (1, 3)) for s in source.tolist()]
    present = ~episodes["object_pos"].isnan().any(-1)  # [E, T+1, 3]
    assert torch.equal(present.sum(-1), counts[:, None].expand(-1, present.shape[1]))
    run_collect(tmp_path / "fixed", "data.generalization=null")  # 3 objects, the same seed
    fixed = stored(tmp_path / "fixed" / "smoke")
    for i in (counts == 3).nonzero().flatten().tolist():
        j = (fixed["source_episode"] == source[i]).nonzero().item()
        assert torch.equal(episodes["pixels"][i], fixed["pixels"][j])
    expect = {"num_objects": 3, "num_objects_range": [1, 3]}
    data = load_dataset(tmp_path / "range" / "smoke", expect=expect)
    assert data.sample(4, horizon=2)["pixels"].shape == (4, 32, 32, 3)
