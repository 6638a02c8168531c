"""A dataset with no object state (pixels and pushes only, e.g. a robot's, imported) is a
first-class dataset: it loads and samples, the ground-truth models refuse it by name, the pixel
models' losses train on it, the report measures what the images allow, and the workspace it
states reaches the model's scene and its planner."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from PIL import Image
from tensordict import TensorDict

from kinet_rl.baselines import ImageForwardLoss, VCDNLoss
from kinet_rl.config_schema import ConfigError
from kinet_rl.configs import config_dir
from kinet_rl.data import (
    DatasetMismatchError,
    ImportSettings,
    PushDataset,
    import_push_folder,
    load_dataset,
    plan_import,
)
from kinet_rl.data.storage import imported_metadata
from kinet_rl.envs import SceneGeometry, SceneSettings
from kinet_rl.evaluation.consistency import keypoint_consistency
from kinet_rl.evaluation.report import TrainingReport, has_object_state
from kinet_rl.keys import ACTION, OBJECT_POS, OBJECT_SHAPE, OBJECT_YAW, PIXELS
from kinet_rl.models import KINetLoss, PushPlanner
from kinet_rl.pipeline import ExperimentSettings, check_dataset_for, run_experiment
from push_folders import HALF_SIZE, write_push_folder

SIZE = 16


@pytest.fixture(scope="module")
def robot_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An imported dataset: 10 episodes of 5 pushes (8 / 1 / 1), 16 px, no object state."""
    tmp = tmp_path_factory.mktemp("robot")
    folder = write_push_folder(tmp / "robot", episodes=10, frames=6, width=SIZE, height=SIZE)
    plan = plan_import(folder, ImportSettings(image_size=SIZE))
    return import_push_folder(plan, tmp / "data", "robot", progress=False)


def test_batches_hold_pixels_and_pushes_only(robot_data: Path) -> None:
    data = load_dataset(robot_data, "train", expect={"image_size": SIZE})
    generator = torch.Generator().manual_seed(0)
    batch = data.sample(8, generator, horizon=3)
    assert batch["pixels"].shape == batch["next", "pixels"].shape == (8, SIZE, SIZE, 3)
    assert batch["future", "pixels"].shape == (8, 2, SIZE, SIZE, 3)
    for key in (OBJECT_POS, OBJECT_YAW, OBJECT_SHAPE, ("next", OBJECT_POS)):
        assert batch.get(key, None) is None
    seq = data.sample_sequences(4, 5, generator)
    assert seq["pixels"].shape == (4, 6, SIZE, SIZE, 3) and seq["action"].shape == (4, 5, 4)
    assert seq.get(OBJECT_POS, None) is None
    assert sum(b.shape[0] for b in data.batches(7)) == len(data) == 40
    assert not has_object_state(data)


@pytest.mark.parametrize(
    ("name", "missing"),
    [
        ("in", "['object_pos']"),
        ("in_full", "['object_pos', 'object_shape', 'object_yaw']"),
        ("visin", "['object_pos']"),
    ],
)
def test_models_that_need_ground_truth_refuse_it_naming_what_is_missing(
    robot_data: Path, tiny_baseline, name: str, missing: str
) -> None:
    model = tiny_baseline(name, image_size=SIZE)
    with pytest.raises(DatasetMismatchError, match="no object state") as info:
        check_dataset_for(model, load_dataset(robot_data))
    assert f"needs {missing}" in str(info.value) and "model=kinet" in str(info.value)


@pytest.mark.parametrize("name", ["kinet", "vcdn", "forw", "forwinv"])
def test_pixel_models_train_on_it(robot_data: Path, tiny_kinet, tiny_baseline, name: str) -> None:
    data = load_dataset(robot_data)
    model = tiny_kinet() if name == "kinet" else tiny_baseline(name, image_size=SIZE)
    check_dataset_for(model, data)  # accepted
    if name == "kinet":
        loss = KINetLoss(model)
    elif name == "vcdn":
        loss = VCDNLoss(model, total_steps=4)
    else:
        loss = ImageForwardLoss(model, inv_weight=1.0 if name == "forwinv" else 0.0)
    losses = loss.train()(data.sample(4, torch.Generator().manual_seed(0)))
    total = sum(v for k, v in losses.items() if k.startswith("loss_"))
    total.backward()
    assert torch.isfinite(total) and losses.get("loss_probe", None) is None


def test_forw_still_trains_its_probe_where_object_positions_exist(
    tiny_baseline, transition_batch
) -> None:
    model = tiny_baseline("forw", image_size=16)
    batch = transition_batch(4)
    batch[OBJECT_POS] = torch.rand(4, 3, 2)
    batch["next", OBJECT_POS] = torch.rand(4, 3, 2)
    losses = ImageForwardLoss(model)(batch)
    assert losses["loss_probe"] > 0


class FixedKeypoints(torch.nn.Module):
    """A keypoint model stub: the detector puts one keypoint at (mean red - 0.5, 0) of a frame;
    the rollout predicts it does not move."""

    def detector(self, pixels: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        x = pixels[..., 0].float().mean(dim=(-2, -1)) / 255 - 0.5
        pos = torch.stack([x, torch.zeros_like(x)], dim=-1)[..., None, :]
        return pos, pos.new_zeros(*pos.shape[:-1], 0)

    def rollout_keypoints(self, pixels: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        start, _ = self.detector(pixels)
        return start[:, None].expand(-1, actions.shape[1] + 1, -1, -1)


def test_keypoint_consistency_compares_the_rollout_with_later_detections(robot_data) -> None:
    data = load_dataset(robot_data, "all")
    scores = keypoint_consistency(FixedKeypoints(), data, (1, 3), num_sequences=16)
    # The stub predicts no motion, so its error is the no-motion error, in pixels.
    assert scores[1]["model"] == pytest.approx(scores[1]["no_motion"]) and scores[3]["model"] > 0
    seq = data.sample_sequences(16, 3, torch.Generator().manual_seed(0))
    red = seq["pixels"][..., 0].float().mean(dim=(-2, -1)) / 255  # [B, 4]
    expected = (SIZE / 2 * (red[:, 3] - red[:, 0]).abs()).mean().item()
    assert scores[3]["no_motion"] == pytest.approx(expected, rel=1e-5)


def test_the_report_without_object_state_gives_what_the_images_measure(
    robot_data: Path, tiny_kinet, tiny_baseline, tmp_path: Path
) -> None:
    data = load_dataset(robot_data, "all")
    geometry = SceneGeometry.of_scene("blocks", "top", SIZE)
    model = tiny_kinet()
    report = TrainingReport(tmp_path, "robot", model, data, data, geometry, (1, 3), 8)
    scores = report.on_validate(step=2)
    assert set(scores) == {"val/keypoint_consistency_1_px", "val/keypoint_no_motion_1_px"}
    results = report.final(step=2)
    assert results["object_state"] is False and 0 < results["reconstruction_mse"] < 1
    assert set(results["keypoint_consistency_px"]) == {1, 3} and set(results["image_mse"]) == {1, 3}
    assert "forward_error_m" not in results and "keypoint_accuracy" not in results
    text = (tmp_path / "report.md").read_text()
    assert "No object state" in text and "Reconstruction error" in text
    assert "| pushes ahead | KINet (px) | no motion (px) |" in text
    forw = TrainingReport(
        tmp_path, "robot", tiny_baseline("forw", image_size=SIZE), data, data, geometry
    )
    assert forw.on_validate(step=2) == {}
    assert "has no keypoints" in "".join(forw.score(data)[1])


def test_a_scene_states_its_own_workspace_only_where_it_has_one() -> None:
    assert "workspace_half_size" not in SceneSettings().as_dict()  # a make_env scene, unchanged
    assert SceneSettings().half_size == 0.20 and SceneSettings(task="ycb").half_size == 0.30
    robot = SceneSettings(workspace_half_size=0.35)
    assert robot.half_size == 0.35 and robot.as_dict()["workspace_half_size"] == 0.35
    assert SceneSettings.from_mapping(robot.as_dict()) == robot
    with pytest.raises(ConfigError, match="workspace_half_size"):
        SceneSettings(workspace_half_size=-1.0)


def test_the_planner_pushes_in_the_workspace_of_the_models_scene(tiny_kinet) -> None:
    model = tiny_kinet()
    model.scene = SceneSettings(image_size=SIZE, workspace_half_size=HALF_SIZE)
    planner = PushPlanner(
        model,
        planner={"planning_horizon": 1, "num_candidates": 8, "optim_steps": 1, "top_k": 2},
        seed=0,
    )
    assert planner.workspace_half_size == HALF_SIZE
    image = torch.zeros(SIZE, SIZE, 3, dtype=torch.uint8)
    push = planner.next_push(image, image)
    assert push.start_xy_m[0] == pytest.approx(push.normalised[0] * HALF_SIZE)


def test_a_scene_crops_its_cameras_frames_as_the_import_did() -> None:
    scene = SceneSettings(image_size=SIZE, source_image_size=(48, 40), crop_box=(4, 0, 40))
    assert SceneSettings.from_mapping(json.loads(json.dumps(scene.as_dict()))) == scene
    frame = np.random.default_rng(0).integers(0, 256, (40, 48, 3), dtype=np.uint8)
    expected = Image.fromarray(frame[:, 4:44]).resize((SIZE, SIZE), Image.Resampling.BOX)
    assert np.array_equal(scene.model_frame(frame), np.asarray(expected))
    small = frame[:SIZE, :SIZE]
    assert scene.model_frame(small) is small  # already the model's size: unchanged
    assert "crop_box" not in SceneSettings().as_dict()
    for bad in ({"crop_box": (4, 0, 40)}, {"source_image_size": (48, 40), "crop_box": (9, 0, 40)}):
        with pytest.raises(ConfigError, match="crop_box"):
            SceneSettings(**bad)


def test_the_planner_takes_the_cameras_own_frames(tiny_kinet) -> None:
    scene = SceneSettings(image_size=SIZE, source_image_size=(48, 40), crop_box=(4, 0, 40))
    budget = {"planning_horizon": 1, "num_candidates": 8, "optim_steps": 1, "top_k": 2}
    rng = np.random.default_rng(1)
    frames = [rng.integers(0, 256, (40, 48, 3), dtype=np.uint8) for _ in range(2)]
    model = tiny_kinet()
    model.scene = scene
    pushes = [
        PushPlanner(model, planner=budget, seed=0).next_push(now, goal)
        for now, goal in (frames, [scene.model_frame(f) for f in frames])
    ]
    assert pushes[0] == pushes[1]
    with pytest.raises(ValueError, match="camera's 48x40 px frames"):
        PushPlanner(model, planner=budget).next_push(frames[0][:, :44], frames[1][:, :44])


def settings_of(*overrides: str) -> ExperimentSettings:
    with initialize_config_dir(config_dir(), version_base="1.3"):
        cfg = compose(config_name="config", overrides=["+exp=smoke", *overrides])
    return ExperimentSettings.from_container(OmegaConf.to_container(cfg, resolve=True))


def test_a_run_on_an_imported_dataset_keeps_its_workspace_and_checks_its_episodes(
    robot_data: Path,
) -> None:
    metadata = imported_metadata(robot_data)
    assert metadata is not None and imported_metadata(robot_data.parent) is None
    root = f"data.root={robot_data.parent}"
    settings = settings_of(root, "data.name=robot", f"env.image_size={SIZE}")
    scene = settings.imported_scene(metadata)
    assert scene == SceneSettings(
        image_size=SIZE,
        workspace_half_size=HALF_SIZE,
        source_image_size=(SIZE, SIZE),  # the recorded frames and the square the import kept
        crop_box=(0, 0, SIZE),
    )
    with pytest.raises(ConfigError, match="env.image_size"):
        settings_of(root, "data.name=robot").imported_scene(metadata)
    with pytest.raises(ConfigError, match="report.horizons"):
        settings_of(root, f"env.image_size={SIZE}", "report.horizons=[1,6]").imported_scene(
            metadata
        )


def test_in_memory_episodes_without_object_state_load_too() -> None:
    episodes = TensorDict(
        {
            PIXELS: torch.zeros(2, 4, 16, 16, 3, dtype=torch.uint8),
            ACTION: torch.zeros(2, 3, 4),
            "source_episode": torch.arange(2),
        },
        batch_size=[2],
    )
    data = PushDataset.from_episodes(episodes)
    assert data.num_objects is None and data.sample(3).get(OBJECT_POS, None) is None
    with pytest.raises(DatasetMismatchError, match="in-memory episodes holds pixels"):
        data.check_keys([OBJECT_POS], "IN")


def test_the_pipeline_refuses_a_ground_truth_model_before_training_and_collects_nothing(
    robot_data: Path, tiny_baseline, tmp_path: Path
) -> None:
    settings = settings_of(
        f"data.root={robot_data.parent}", "data.name=robot", f"env.image_size={SIZE}"
    )

    def never(model):
        raise AssertionError("no loss may be built for a model the data cannot train")

    with pytest.raises(DatasetMismatchError, match=r"needs \['object_pos'\].*no object state"):
        run_experiment(settings, lambda: tiny_baseline("in"), never, tmp_path / "run")
    assert sorted(p.name for p in robot_data.parent.iterdir()) == ["robot"]  # no smoke_2obj
