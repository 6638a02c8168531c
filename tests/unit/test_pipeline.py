"""Typed settings of the pipeline built from every experiment config, and checkpoints' scenes."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from kinet_rl.atomic import DirectoryInUseError, directory_lock
from kinet_rl.configs import config_dir
from kinet_rl.envs import SceneSettings
from kinet_rl.models import KINetWorldModel
from kinet_rl.models.checkpointing import checkpoint_scene
from kinet_rl.pipeline import (
    ExperimentSettings,
    check_config,
    collect_datasets,
    dataset_jobs,
    held_out_sets,
    run_experiment,
)

EXPERIMENTS = sorted(p.stem for p in (Path(config_dir()) / "exp").glob("*.yaml"))


def container_of(*overrides: str) -> dict:
    with initialize_config_dir(config_dir(), version_base="1.3"):
        cfg = compose(config_name="config", overrides=list(overrides))
    return OmegaConf.to_container(cfg, resolve=True)


def settings_of(*overrides: str) -> ExperimentSettings:
    return ExperimentSettings.from_container(container_of(*overrides))


@pytest.mark.parametrize("exp", [None, *EXPERIMENTS])
def test_every_experiment_becomes_typed_settings(exp):
    settings = settings_of(*([] if exp is None else [f"+exp={exp}"]))
    assert settings.name == ("default" if exp is None else exp)
    assert settings.scene == settings.rearrangement.scene
    assert "_target_" not in settings.env
    assert settings.dataset_path == Path(settings.data["root"]) / settings.data["name"]
    identity = settings.identity()
    assert identity["model"]["_target_"].startswith("kinet_rl.")
    assert identity["batch_size"] == settings.trainer.batch_size
    assert isinstance(settings.report.horizons, tuple)


def test_default_settings_match_the_config_files():
    settings = settings_of("trainer.steps=7", "eval.episodes=3", "env.camera=side")
    assert settings.trainer.steps == 7
    assert settings.rearrangement.episodes == 3
    assert settings.scene == SceneSettings(camera="side")


def test_an_unknown_eval_key_is_refused_with_the_allowed_ones():
    with pytest.raises(
        ValueError, match=r"eval.epsiodes: unknown key \(set to 3\) \(did you mean episodes\?\)"
    ):
        settings_of("+eval.epsiodes=3")


def test_a_checkpoint_stores_its_scene_as_typed_data(tmp_path):
    torch.manual_seed(0)
    model = KINetWorldModel(num_keypoints=2, channels=8, embed_dim=8, hidden_dim=8, num_hidden=1)
    scene = SceneSettings(task="ycb", camera="side", image_size=96, num_objects=4)
    model.save_checkpoint(tmp_path / "with.pt", scene=scene)
    model.save_checkpoint(tmp_path / "without.pt")
    assert checkpoint_scene(tmp_path / "with.pt") == scene
    assert checkpoint_scene(tmp_path / "without.pt") is None
    state = torch.load(tmp_path / "with.pt", weights_only=True)
    assert "config" not in state and state["scene"] == scene.as_dict()


def test_episode_negatives_without_grouped_batches_are_refused_before_work():
    episode = "loss.ctr_negatives=episode"
    with pytest.raises(ValueError, match="trainer.steps_per_episode=1 samples one step"):
        settings_of(episode, "trainer.steps_per_episode=1")
    settings_of(episode, "trainer.steps_per_episode=4")
    settings_of("+exp=blocks_topview_no_ctr", episode)  # no contrastive term, nothing to check
    with pytest.raises(ValueError, match="trainer.horizon=1"):
        settings_of("trainer.horizon=1")  # the default rollout loss needs the following pushes
    assert settings_of("trainer.horizon=1", "loss.rollout_weight=0").trainer.horizon == 1


def test_a_second_training_run_in_the_same_directory_is_refused_before_any_work(tmp_path):
    settings = settings_of("+exp=smoke", f"data.root={tmp_path / 'data'}")

    def never(*args):
        raise AssertionError("nothing may be built in a busy run directory")

    busy = pytest.raises(DirectoryInUseError, match="run is in use.*is training there")
    with directory_lock(tmp_path / "run", "training"), busy:
        run_experiment(settings, never, never, tmp_path / "run")
    assert not (tmp_path / "data").exists()  # refused before collecting


@pytest.mark.parametrize("model", ["kinet", "vcdn"])
def test_a_count_range_is_for_the_main_dataset_of_a_keypoint_model(model):
    config = container_of(
        "+exp=blocks_topview", f"model={model}", f"loss={model}", "data.num_objects_range=[1,5]"
    )
    settings = check_config(config)
    assert settings.dataset_expect == {
        "task": "blocks", "camera": "top", "image_size": 64, "num_objects": 5,
        "num_objects_range": [1, 5],
    }  # fmt: skip
    main, *generalization = dataset_jobs(settings.env, settings.data)
    assert main.arguments["num_objects_range"] == [1, 5]
    assert {job.arguments["num_objects_range"] for job in generalization} == {None}
    fixed = settings_of("+exp=blocks_topview")
    assert (
        fixed.dataset_expect["num_objects"] == 3
        and fixed.dataset_expect["num_objects_range"] is None
    )


def test_settings_name_their_model_and_datasets_as_typed_values():
    settings = settings_of(
        "data.seed=7",
        "++data.generalization={five: {env: {num_objects: 5}}, side: {env: {camera: side}, "
        "num_episodes: 4, seed: 30}}",
    )
    assert settings.model_name == "KINetWorldModel"
    main, five, side = dataset_jobs(settings.env, settings.data)
    assert settings.main_dataset == main and main.path == settings.dataset_path
    assert (main.name, main.seed) == ("blocks_top64", 7)
    assert (main.num_episodes, main.num_workers) == (100, 2)
    assert main.policy == settings.data["policy"]
    assert main.pushes_per_episode == settings.env["max_steps"]
    assert (five.name, five.seed, five.num_episodes) == ("five", 8, 100)
    assert (side.name, side.seed, side.num_episodes) == ("side", 30, 4)
    assert five.scene_differences(main) == ["num_objects"]
    assert side.scene_differences(main) == ["camera"] and main.scene_differences(main) == []


@pytest.mark.slow  # collects episodes on MuJoCo
def test_the_report_scores_the_generalization_sets_of_the_training_scene(
    tmp_path, tiny_kinet, tiny_baseline
):
    """A set of another camera is never scored; one of another object count only for a model
    that handles any count; every episode of a scored set is used (none was trained on)."""
    settings = settings_of(
        f"data.root={tmp_path}", "data.num_episodes=3", "data.num_workers=1",
        "data.chunk_episodes=1", "env.max_steps=3", "env.image_size=32", "report.horizons=[1]",
        "data.splits={train: 0.34, val: 0.33, test: 0.33}",
        "++data.generalization={same: {num_episodes: 4}, five: {env: {num_objects: 5}}, "
        "side: {env: {camera: side}}}",
    )  # fmt: skip
    collect_datasets(settings.env, settings.data)
    by_count = held_out_sets(settings, tiny_kinet())
    assert sorted(by_count) == ["five", "same"]
    assert by_count["same"].num_episodes == 4 and by_count["five"].num_objects == 5
    assert sorted(held_out_sets(settings, tiny_baseline("in", num_objects=3))) == ["same"]
