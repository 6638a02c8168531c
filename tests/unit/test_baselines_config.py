"""Every baseline model and loss config composes and instantiates into a working pair."""

from __future__ import annotations

import pytest
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate

from kinet_rl.baselines import FullStateInteractionModel, ObjectForwardLoss
from kinet_rl.envs.geometry import SceneGeometry

IN_FULL_EXPERIMENTS = [
    f"{task}_{camera}view_in_full" for task in ("blocks", "ycb") for camera in ("top", "side")
]


@pytest.mark.parametrize("name", ["forw", "forwinv", "in", "in_full", "visin", "vcdn"])
def test_model_and_loss_configs_instantiate(name, conf_dir):
    with initialize_config_dir(config_dir=str(conf_dir), version_base="1.3"):
        cfg = compose("config", overrides=[f"model={name}", f"loss={name}", "env.image_size=32"])
    model = instantiate(cfg.model, _convert_="all")
    loss = instantiate(cfg.loss, world_model=model, _convert_="all")
    assert loss.world_model is model
    geometry = SceneGeometry.of_scene(cfg.env.task, cfg.env.camera, cfg.env.image_size)
    assert callable(model.object_rollout(geometry))
    if "num_objects" in model.config:
        assert model.config["num_objects"] == cfg.env.num_objects


def test_vcdn_perception_stage_follows_the_trainer_steps(conf_dir):
    with initialize_config_dir(config_dir=str(conf_dir), version_base="1.3"):
        cfg = compose("config", overrides=["model=vcdn", "loss=vcdn", "trainer.steps=300"])
    loss = instantiate(cfg.loss, world_model=instantiate(cfg.model), _convert_="all")
    assert loss.perception_steps == 150


@pytest.mark.parametrize("exp", IN_FULL_EXPERIMENTS)
def test_every_in_full_experiment_composes_and_instantiates_like_in(exp, conf_dir):
    """``+exp=<scene>_in_full`` is ``+exp=<scene>_in`` with the IN-full model: same data, env,
    trainer and loss."""
    with initialize_config_dir(config_dir=str(conf_dir), version_base="1.3"):
        cfg = compose("config", overrides=[f"+exp={exp}"])
        in_cfg = compose("config", overrides=[f"+exp={exp.removesuffix('_full')}"])
    assert cfg.exp_name == exp
    model = instantiate(cfg.model, _convert_="all")
    loss = instantiate(cfg.loss, world_model=model, _convert_="all")
    assert isinstance(model, FullStateInteractionModel) and isinstance(loss, ObjectForwardLoss)
    assert model.config["task"] == cfg.env.task and model.num_objects == cfg.env.num_objects
    for group in ("env", "data", "trainer", "loss"):
        assert cfg[group] == in_cfg[group], group
