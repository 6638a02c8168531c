"""Tests for the rearrangement settings and their conditions (no simulation)."""

from __future__ import annotations

import pytest
from omegaconf import OmegaConf

from kinet_rl.config_schema import ConfigError
from kinet_rl.envs import SceneSettings
from kinet_rl.rearrangement.settings import (
    DEFAULT_METHODS,
    Condition,
    RearrangementSettings,
    generalization_key,
)


@pytest.fixture
def yaml_settings(conf_dir):
    """Settings from ``conf/eval/rearrange.yaml`` and ``conf/env/blocks.yaml``, with overrides."""

    def make(**eval_overrides) -> RearrangementSettings:
        eval_cfg = OmegaConf.to_container(OmegaConf.load(conf_dir / "eval" / "rearrange.yaml"))
        env_cfg = OmegaConf.to_container(OmegaConf.load(conf_dir / "env" / "blocks.yaml"))
        return RearrangementSettings.from_dicts({**eval_cfg, **eval_overrides}, env_cfg)

    return make


def test_yaml_settings_build_the_comparison_and_table_ii_conditions(yaml_settings) -> None:
    settings = yaml_settings()
    assert settings.task.num_steps == 40 and settings.scene.num_objects == 3
    conditions = settings.conditions()
    assert conditions[0].name == "comparison" and conditions[0].role == "comparison"
    assert set(conditions[0].methods) == set(DEFAULT_METHODS)
    names = {c.name for c in conditions}
    assert {f"n{n}_geom_{g}" for n in range(1, 6) for g in ("train", "gen")} <= names
    assert "background_random" in names
    assert [c.name for c in settings.conditions(generalization=False)] == ["comparison"]


def test_condition_names_follow_their_role() -> None:
    scene = SceneSettings(num_objects=2, geometry="gen", background="random")
    assert generalization_key(2, "gen") == "n2_geom_gen"
    assert Condition(scene, "comparison", ("random",), 1).name == "comparison"
    assert Condition(scene, "generalization", ("random",), 1).name == "n2_geom_gen"
    assert Condition(scene, "background", ("random",), 1).name == "background_random"


def test_validation_and_test_episodes_have_disjoint_seeds(yaml_settings) -> None:
    assert yaml_settings().split == "test"  # what the docs report
    validation, test = yaml_settings(split="validation"), yaml_settings(split="test")
    seeds = [range(s.first_seed, s.first_seed + 1000) for s in (validation, test)]
    assert not set(seeds[0]) & set(seeds[1])
    with pytest.raises(ValueError, match="split: got 'train', expected one of 'validation'"):
        yaml_settings(split="train")


def test_unknown_settings_are_reported(yaml_settings) -> None:
    with pytest.raises(ValueError, match="episodez: unknown key"):
        yaml_settings(episodez=3)
    with pytest.raises(ValueError, match="episodes: got 0, expected an integer of at least 1"):
        yaml_settings(episodes=0)


def test_as_dict_round_trips_through_from_dicts(yaml_settings) -> None:
    settings = yaml_settings(num_objects=[1, 2], backgrounds=[])
    plain = settings.as_dict()
    eval_cfg = {k: v for k, v in plain.items() if k not in ("scene", "task")}
    assert (
        RearrangementSettings.from_dicts({**eval_cfg, **plain["task"]}, plain["scene"]) == settings
    )


def test_ycb_object_lists_reach_every_condition_and_are_checked(conf_dir) -> None:
    eval_cfg = OmegaConf.to_container(OmegaConf.load(conf_dir / "eval" / "rearrange.yaml"))
    env_cfg = OmegaConf.to_container(OmegaConf.load(conf_dir / "env" / "ycb.yaml"))
    held_out = ["004_sugar_box", "007_tuna_fish_can", "025_mug"]
    settings = RearrangementSettings.from_dicts(eval_cfg, {**env_cfg, "ycb_objects": held_out})
    assert {c.scene.ycb_objects for c in settings.conditions()} == {tuple(held_out)}
    default = RearrangementSettings.from_dicts(eval_cfg, env_cfg)
    assert default.scene.ycb_objects is None and default.as_dict() != settings.as_dict()
    with pytest.raises(ConfigError, match="ycb_objects.*null for task blocks"):
        SceneSettings(task="blocks", ycb_objects=("025_mug",))
    with pytest.raises(ConfigError, match="ycb_objects.*non-empty list"):
        SceneSettings(task="ycb", ycb_objects=())
