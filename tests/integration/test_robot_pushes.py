"""A robot's own pushes end to end (slow): :class:`PushRecorder` writes a push folder of frames
rendered by the simulator with the object state left out, ``python -m kinet_rl.import_data``
turns it into a dataset, ``python -m kinet_rl.train`` trains KINet on it through the pipeline,
and ``python -m kinet_rl.plan`` plans a push in the robot's metres."""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from kinet_rl import import_data, plan
from kinet_rl.data import PushRecorder, RandomPushPolicy, load_dataset
from kinet_rl.data.collection import seeded_env
from kinet_rl.data.storage import open_episodes
from kinet_rl.envs import SceneSettings, make_env
from kinet_rl.keys import PIXELS
from kinet_rl.models import KINetWorldModel

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
#: The simulator's workspace (blocks), in which the pushes are drawn.
SIM_HALF_SIZE = 0.20
#: The workspace the push folder states: larger than the simulator's, so that the normalised
#: actions the model learns (metres / 0.25) differ from the simulator's and the test can tell
#: which half size reached the planner.
ROBOT_HALF_SIZE = 0.25
EPISODES, PUSHES, RENDER, SIDE_BAND, SIZE = 12, 5, 40, 4, 32


def record_push_folder(root: Path) -> Path:
    """12 episodes of 5 pushes rendered at 40 px and widened to 48 x 40 px (a non-square
    camera), recorded with pixels and pushes (metres) only."""
    env_fn = functools.partial(
        make_env, task="blocks", num_objects=3, camera="top", image_size=RENDER, max_steps=PUSHES
    )
    env = seeded_env(env_fn, seed=7, first_episode=0, episode_stride=1)
    policy = RandomPushPolicy(SIM_HALF_SIZE)
    recorder = PushRecorder(root, ROBOT_HALF_SIZE, camera="sim_top")
    try:
        for _ in range(EPISODES):
            rollout = env.rollout(PUSHES, policy)
            frames = [*rollout[PIXELS], rollout[-1]["next", PIXELS]]
            wide = [
                np.pad(f.numpy(), ((0, 0), (SIDE_BAND, SIDE_BAND), (0, 0)), constant_values=90)
                for f in frames
            ]
            for frame, action in zip(wide, rollout["action"], strict=False):
                recorder.append(frame, (action * SIM_HALF_SIZE).double().numpy())
            recorder.close_episode(wide[-1])
    finally:
        env.close()
    return root


def train(data_root: Path, run: Path, *overrides: str) -> str:
    """``python -m kinet_rl.train +exp=smoke`` on the imported dataset; returns its output."""
    command = [
        sys.executable,
        "-m",
        "kinet_rl.train",
        "+exp=smoke",
        f"data.root={data_root}",
        "data.name=robot",
        f"env.image_size={SIZE}",
        f"hydra.run.dir={run}",
        "estimate=false",
        *overrides,
    ]
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "OMP_NUM_THREADS": "1"}
    result = subprocess.run(
        command, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        timeout=300,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout[-6000:]
    return result.stdout


@pytest.fixture(scope="module")
def imported(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The recorded folder, imported (centre crop, 32 px): the dataset's folder."""
    tmp = tmp_path_factory.mktemp("robot")
    folder = record_push_folder(tmp / "robot")
    assert len(list(folder.glob("episode_*"))) == EPISODES
    argv = [str(folder), "--root", str(tmp / "data"), "--crop", "center", "--image-size", "32"]
    return import_data.main(argv)


def test_recorded_pushes_import_train_and_plan_in_the_robots_metres(
    imported: Path, tmp_path: Path
) -> None:
    data = load_dataset(imported, "train")
    assert not data.has_object_state and data.episode_length == PUSHES
    assert data.image_size == SIZE and data.num_episodes == 10  # 12 x 0.8, by episode
    assert data.sample(64)["action"].abs().max() <= SIM_HALF_SIZE / ROBOT_HALF_SIZE + 1e-6

    run = tmp_path / "run"
    output = train(imported.parent, run)
    assert "robot: 12 episodes x 5 pushes, imported (nothing to collect)" in output  # the plan
    assert "was imported (python -m kinet_rl.import_data), not collected" in output
    assert "smoke_2obj" not in output  # the smoke experiment's generalization set: skipped
    assert not (imported.parent / "smoke_2obj").exists()
    results = json.loads((run / "results.json").read_text())
    assert results["object_state"] is False and "rearrangement" not in results
    consistency = results["keypoint_consistency_px"]
    assert set(consistency) == {"1", "3"} and all(v["model"] >= 0 for v in consistency.values())
    report = (run / "report.md").read_text()
    assert "No object state" in report and "Reconstruction error" in report

    model = KINetWorldModel.from_checkpoint(run / "kinet.pt")
    width = RENDER + 2 * SIDE_BAND
    assert model.scene == SceneSettings(
        image_size=SIZE,
        workspace_half_size=ROBOT_HALF_SIZE,
        source_image_size=(width, RENDER),
        crop_box=(SIDE_BAND, 0, RENDER),  # the centre crop of the 48 x 40 px frames
    )
    # The first training episode is the recorded episode 0: plan from its stored (cropped,
    # resized) frames and from the camera's own frames, which the planner crops as the import did.
    episode = open_episodes(imported)[PIXELS][0]
    stored = {"now": episode[0], "goal": episode[-1]}
    recorded = imported.parent.parent / "robot" / "episode_000000"
    camera = {"now": recorded / "frame_000000.png", "goal": recorded / f"frame_{PUSHES:06d}.png"}
    for name, frame in stored.items():
        Image.fromarray(frame.numpy()).save(tmp_path / f"{name}.png")
    with Image.open(camera["now"]) as frame:
        assert frame.size == (width, RENDER)
    checkpoint = str(run / "kinet.pt")
    pushes = [
        plan.main(["--checkpoint", checkpoint, "--image", str(now), "--goal", str(goal)])[0]
        for now, goal in (
            (tmp_path / "now.png", tmp_path / "goal.png"),
            (camera["now"], camera["goal"]),
        )
    ]
    assert pushes[0]["normalised"] == pushes[1]["normalised"]  # the same images reached the model
    normalised = np.array(pushes[0]["normalised"])
    assert np.abs(normalised).max() <= 1
    metres = np.array([*pushes[0]["start_xy_m"], *pushes[0]["end_xy_m"]])
    assert np.allclose(metres, normalised * ROBOT_HALF_SIZE)  # the robot's units


@pytest.mark.parametrize("model", ["vcdn", "forw", "forwinv"])
def test_the_other_pixel_models_train_on_it_through_the_pipeline(
    imported: Path, tmp_path: Path, model: str
) -> None:
    run = tmp_path / "run"
    train(imported.parent, run, f"model={model}", f"loss={model}")
    results = json.loads((run / "results.json").read_text())
    assert results["object_state"] is False and "forward_error_m" not in results
    report = (run / "report.md").read_text()
    if model == "vcdn":
        assert set(results["keypoint_consistency_px"]) == {"1", "3"}
        assert "| pushes ahead | V-CDN (px) |" in report
    else:
        assert "has no keypoints and no decoder" in report
        assert (run / "model.pt").is_file()
