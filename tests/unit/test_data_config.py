"""Every conf/exp/*.yaml composes and gives collect arguments the library accepts."""

from __future__ import annotations

import inspect
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate
from omegaconf import OmegaConf

from kinet_rl.configs import config_dir
from kinet_rl.data import RandomPushPolicy, collect_dataset

#: Parametrization needs the experiments at collection time, before fixtures exist.
EXPERIMENTS = sorted(p.stem for p in (Path(config_dir()) / "exp").glob("*.yaml"))


@pytest.fixture
def compose_config(conf_dir):
    def compose_with(overrides: list[str]):
        with initialize_config_dir(config_dir=str(conf_dir), version_base="1.3"):
            return compose(config_name="config", overrides=overrides)

    return compose_with


@pytest.mark.parametrize("overrides", [[]] + [[f"+exp={name}"] for name in EXPERIMENTS])
def test_config_composes_into_valid_collect_arguments(overrides: list[str], compose_config) -> None:
    cfg = compose_config(overrides)
    data = OmegaConf.to_container(cfg.data, resolve=True)
    generalization = data.pop("generalization")
    assert set(data) <= set(inspect.signature(collect_dataset).parameters)
    RandomPushPolicy(0.2, **data["policy"])
    env_fn = instantiate(cfg.env, _partial_=True)
    assert env_fn.func.__name__ == "make_env"
    for extra in generalization.values():
        assert set(extra) <= {"num_episodes", "env", "seed"}
        assert set(extra.get("env", {})) <= set(inspect.signature(env_fn.func).parameters)


def test_paper_experiments_have_the_paper_sizes(compose_config) -> None:
    cfg = compose_config(["+exp=blocks_topview"])
    assert cfg.data.num_episodes == 8000 and cfg.env.camera == "top" and cfg.env.num_objects == 3
    sizes = {name: extra.num_episodes for name, extra in cfg.data.generalization.items()}
    assert {f"blocks_topview_{n}obj" for n in (1, 2, 4, 5)} <= set(sizes)
    assert set(sizes.values()) == {400}
    assert compose_config(["+exp=ycb_sideview"]).env.task == "ycb"
