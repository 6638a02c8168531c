"""Every baseline model and loss config composes and instantiates into a working pair."""

from __future__ import annotations

import pytest
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate


@pytest.mark.parametrize("name", ["forw", "forwinv", "in", "visin"])
def test_model_and_loss_configs_instantiate(name, conf_dir):
    with initialize_config_dir(config_dir=str(conf_dir), version_base="1.3"):
        cfg = compose("config", overrides=[f"model={name}", f"loss={name}", "env.image_size=32"])
    model = instantiate(cfg.model, _convert_="all")
    loss = instantiate(cfg.loss, world_model=model, _convert_="all")
    assert loss.world_model is model
    assert callable(model.object_rollout())
    if "num_objects" in model.config:
        assert model.config["num_objects"] == cfg.env.num_objects
