"""The models shipped with the package load safely, match their cards, and plan (slow)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from PIL import Image
from safetensors.torch import load_file

from kinet_rl import plan
from kinet_rl.envs.settings import SceneSettings
from kinet_rl.models import KINetWorldModel, PushPlanner, model_card, pretrained_names
from kinet_rl.models.pretrained import pretrained_path, resolve_checkpoint
from kinet_rl.pipeline import pretrained_keypoint_accuracy
from kinet_rl.rearrangement.episodes import make_episode
from kinet_rl.rearrangement.policies import PlannerPolicy, RandomPolicy
from kinet_rl.rearrangement.settings import TaskSettings
from planned_episodes import final_distances_mm, validation_seeds

pytestmark = pytest.mark.slow

CARD_FIELDS = {"name", "model", "command", "seed", "data", "training", "scene", "metrics", "check"}


#: Rearrangement episodes each shipped model plans from images: validation seeds, T = 10.
EPISODES, TASK = 4, TaskSettings(num_steps=10)


def shipped() -> list:
    """The shipped models' names as parameters; a YCB model's needs the assets (``ycb``)."""
    return [
        pytest.param(name, marks=pytest.mark.ycb)
        if model_card(name)["scene"]["task"] == "ycb"
        else name
        for name in pretrained_names()
    ]


def test_the_blocks_models_are_shipped() -> None:
    assert {"blocks_topview", "blocks_sideview"} <= set(pretrained_names())


@pytest.mark.parametrize("name", shipped())
def test_shipped_model_loads_with_weights_only_and_reproduces_its_card(
    name: str, tmp_path: Path
) -> None:
    folder = pretrained_path(name)
    assert {p.name for p in folder.iterdir()} == {"config.json", "model.safetensors", "README.md"}
    load_file(folder / "model.safetensors")  # tensors only: no pickled code in the folder
    card = model_card(name)
    assert set(card) >= CARD_FIELDS and card["name"] == name
    model = KINetWorldModel.from_pretrained(name)
    assert not model.training
    check = card["check"]
    accuracy = pretrained_keypoint_accuracy(name, tmp_path)
    assert accuracy == pytest.approx(check["keypoint_accuracy"], abs=check["tolerance"])


def test_unknown_pretrained_name_lists_the_shipped_ones() -> None:
    with pytest.raises(ValueError, match="shipped: .*blocks_topview"):
        resolve_checkpoint("pretrained:no_such_model")
    assert resolve_checkpoint("runs/x/kinet.pt") == Path("runs/x/kinet.pt")
    assert resolve_checkpoint("pretrained:blocks_topview") == pretrained_path("blocks_topview")


def test_plan_cli_plans_with_a_shipped_model(tmp_path: Path, capsys) -> None:
    scene = SceneSettings.from_mapping(model_card("blocks_topview")["scene"])
    episode = make_episode(scene, TaskSettings(), 50_000)
    try:
        Image.fromarray(episode.start["pixels"]).save(tmp_path / "now.png")
        Image.fromarray(episode.goal_pixels).save(tmp_path / "goal.png")
    finally:
        episode.close()
    args = ["--checkpoint", "pretrained:blocks_topview", "--image", str(tmp_path / "now.png")]
    args += ["--goal", str(tmp_path / "goal.png"), "--candidates", "32", "--iterations", "2"]
    (push,) = plan.main([*args, "--top-k", "4"])
    assert json.loads(capsys.readouterr().out) == push
    assert all(-1.0 <= v <= 1.0 for v in push["normalised"])
    assert push["start_xy_m"] == pytest.approx([0.2 * v for v in push["normalised"][:2]])


@pytest.mark.parametrize("name", shipped())
def test_shipped_model_plans_from_images_closer_than_random_pushes(name: str) -> None:
    model = KINetWorldModel.from_pretrained(name)
    policies = {
        "planned": PlannerPolicy(PushPlanner(model, seed=0)),
        "random": RandomPolicy(validation_seeds(EPISODES)),
    }
    planned, random = (
        final_distances_mm(policy, model.scene, TASK, EPISODES) for policy in policies.values()
    )
    print(f"{name}: planned {planned.round(1)} mm, random pushes {random.round(1)} mm")
    assert planned.mean() < random.mean(), (planned, random)
