"""``python -m kinet_rl.plan``: the checkpoint's planning defaults, image sizes, ``--resize``."""

from __future__ import annotations

import json
import logging

import pytest
from PIL import Image

from kinet_rl import plan
from kinet_rl.envs import SceneSettings
from kinet_rl.models import KINetWorldModel, PushPlanner
from kinet_rl.planners import VALIDATED_PLANNER, PlanningDefaults

BUDGET = {**VALIDATED_PLANNER, "num_candidates": 12, "top_k": 3, "optim_steps": 2}


@pytest.fixture
def checkpoint(tiny_kinet, tmp_path):
    """A tiny KINet trained on 16 px YCB scenes, planning with the keypoint distance at 12 x 2."""
    model = tiny_kinet()
    model.planning = PlanningDefaults("keypoints_distance", BUDGET)
    path = tmp_path / "kinet.pt"
    model.save_checkpoint(path, SceneSettings(task="ycb", image_size=16))
    return path


def write_images(tmp_path, random_images, sizes):
    paths = []
    for i, size in enumerate(sizes):
        path = tmp_path / f"image{i}.png"
        Image.fromarray(random_images((), i, size=size).numpy()).save(path)
        paths.append(str(path))
    return paths


def test_plan_uses_the_objective_budget_and_workspace_of_the_checkpoint(
    checkpoint, tmp_path, random_images, monkeypatch, capsys
) -> None:
    image, goal = write_images(tmp_path, random_images, (16, 16))
    built = []

    def push_planner(*args, **kwargs):
        built.append(PushPlanner(*args, **kwargs))
        return built[-1]

    monkeypatch.setattr(plan, "PushPlanner", push_planner)
    (push,) = plan.main(["--checkpoint", str(checkpoint), "--image", image, "--goal", goal])
    planner = built[0]
    assert planner.objective == "keypoints_distance"
    assert (planner.planner.num_candidates, planner.planner.top_k) == (12, 3)
    assert planner.planner.optim_steps == 2 and planner.planner.return_best
    assert planner.workspace_half_size == pytest.approx(0.30)  # YCB's, from the checkpoint
    assert push["start_xy_m"][0] == pytest.approx(0.30 * push["normalised"][0])
    assert json.loads(capsys.readouterr().out)["image"] == image
    plan.main(["--checkpoint", str(checkpoint), "--image", image, "--goal", goal, "--top-k", "5"])
    assert built[1].planner.top_k == 5 and built[1].planner.num_candidates == 12


def test_images_of_another_size_are_refused_naming_both_sizes(
    checkpoint, tmp_path, random_images
) -> None:
    big, image, small_goal = write_images(tmp_path, random_images, (24, 16, 12))
    with pytest.raises(SystemExit, match="24x24 px but the model was trained on 16x16"):
        plan.main(["--checkpoint", str(checkpoint), "--image", big, "--goal", image])
    with pytest.raises(SystemExit, match="goal image is 12x12 px but the current image is 16x16"):
        plan.main(["--checkpoint", str(checkpoint), "--image", image, "--goal", small_goal])


def test_resize_resizes_to_the_models_size_and_says_so(
    checkpoint, tmp_path, random_images, caplog
) -> None:
    big, small_goal = write_images(tmp_path, random_images, (24, 12))
    with caplog.at_level(logging.INFO, logger="kinet_rl.plan"):
        (push,) = plan.main(
            ["--checkpoint", str(checkpoint), "--image", big, "--goal", small_goal, "--resize"]
        )
    assert all(-1.0 <= v <= 1.0 for v in push["normalised"])
    assert "from 24x24 to 16x16 px (--resize)" in caplog.text
    assert "from 12x12 to 16x16 px (--resize)" in caplog.text


def test_a_model_folder_plans_as_its_checkpoint_does(
    checkpoint, tmp_path, random_images, capsys
) -> None:
    image, goal = write_images(tmp_path, random_images, (16, 16))
    folder = KINetWorldModel.from_checkpoint(checkpoint).save_pretrained(tmp_path / "model")
    args = ["--image", image, "--goal", goal, "--seed", "3"]
    from_file = plan.main(["--checkpoint", str(checkpoint), *args])
    from_folder = plan.main(["--checkpoint", str(folder), *args])
    assert from_folder == from_file
    capsys.readouterr()
