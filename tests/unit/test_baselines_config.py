"""Every baseline model and loss config composes and instantiates into a working pair."""

from __future__ import annotations

import pytest
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate

from kinet_rl.envs.geometry import SceneGeometry


@pytest.mark.parametrize("name", ["forw", "forwinv", "in", "visin", "vcdn"])
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
