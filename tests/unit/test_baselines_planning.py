"""Baseline model envs and the baseline MPC controller (no simulation; tiny models)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

from kinet_rl.baselines.model_env import (
    FeatureModelEnv,
    KeypointGraphModelEnv,
    ObjectModelEnv,
    make_baseline_env,
)
from kinet_rl.envs import SceneSettings
from kinet_rl.keys import (
    GOAL_IMAGE_FEAT,
    GOAL_KP_POS,
    GOAL_OBJECT_POS,
    IMAGE_FEAT,
    KP_EDGE_TYPE,
    KP_POS,
    OBJECT_FEAT,
    OBJECT_POS,
    OBJECT_SHAPE,
    OBJECT_YAW,
)
from kinet_rl.pipeline import evaluate_rearrangement
from kinet_rl.planners import GraphMPCPlanner, StateModelEnv
from kinet_rl.rearrangement.controllers import BaselineMPCController
from kinet_rl.rearrangement.methods import METHODS, MethodContext
from kinet_rl.rearrangement.settings import RearrangementSettings

SIZE, N = 32, 3
PLANNER = {"planning_horizon": 2, "optim_steps": 2, "num_candidates": 16, "top_k": 4}


def observation(seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {
        "pixels": rng.integers(0, 255, (SIZE, SIZE, 3), dtype=np.uint8),
        "object_pos": rng.uniform(-0.15, 0.15, (N, 2)).astype(np.float32),
        "object_yaw": rng.uniform(-np.pi, np.pi, N).astype(np.float32),
        "object_shape": rng.uniform(0.01, 0.04, (N, 8)).astype(np.float32),
    }


def start_state(env, seed: int = 0):
    obs, goal = observation(seed), observation(seed + 1)
    pixels = torch.from_numpy(obs["pixels"])
    if isinstance(env, ObjectModelEnv):
        state = {key: torch.from_numpy(obs[key]) for key in env.model.state_keys}
        return env.observe(
            pixels,
            torch.from_numpy(obs["object_pos"]),
            torch.from_numpy(goal["object_pos"]),
            **state,
        )
    return env.observe(pixels, torch.from_numpy(goal["pixels"]))


STATE_KEYS = {
    ObjectModelEnv: [OBJECT_POS, OBJECT_FEAT, GOAL_OBJECT_POS],
    FeatureModelEnv: [IMAGE_FEAT, GOAL_IMAGE_FEAT],
    KeypointGraphModelEnv: [KP_POS, KP_EDGE_TYPE, GOAL_KP_POS],
}


@pytest.mark.parametrize("name", ["forw", "forwinv", "in", "in_full", "visin", "vcdn"])
def test_model_env_specs_and_state_keys(name: str, tiny_baseline) -> None:
    env = make_baseline_env(tiny_baseline(name))
    state = start_state(env)
    keys = STATE_KEYS[type(env)]
    assert set(keys) == set(env.state_spec.keys(True, True))
    assert env.state_spec.is_in(state)
    assert not env.batch_locked and isinstance(env, StateModelEnv)
    check_env_specs(env, tensordict=env.reset(state))


def test_object_env_reward_is_minus_mean_goal_distance_of_the_prediction(tiny_baseline) -> None:
    model = tiny_baseline("in")
    env = ObjectModelEnv(model)
    state = start_state(env).expand(5).clone()
    state["action"] = torch.rand(5, 4) * 2 - 1
    out = env.step(state)
    pred = model.predict(state[OBJECT_POS], state[OBJECT_FEAT], state["action"])
    expected = -(pred - state[GOAL_OBJECT_POS]).norm(dim=-1).mean(-1, keepdim=True)
    torch.testing.assert_close(out["next", "reward"], expected)
    torch.testing.assert_close(out["next", OBJECT_POS], pred)


def test_feature_env_reward_is_minus_squared_feature_distance(tiny_baseline) -> None:
    model = tiny_baseline("forw")
    env = FeatureModelEnv(model)
    state = start_state(env).expand(5).clone()
    state["action"] = torch.rand(5, 4) * 2 - 1
    out = env.step(state)
    pred = model.predict(state[IMAGE_FEAT], state["action"])
    expected = -(pred - state[GOAL_IMAGE_FEAT]).pow(2).sum(-1, keepdim=True)
    torch.testing.assert_close(out["next", "reward"], expected)


def test_visin_state_carries_crop_features_of_the_current_image(tiny_baseline) -> None:
    env = ObjectModelEnv(tiny_baseline("visin"))
    a, b = start_state(env, 0), start_state(env, 5)
    assert a[OBJECT_FEAT].shape == (N, 4)
    assert not torch.allclose(a[OBJECT_FEAT], b[OBJECT_FEAT])


def test_in_full_state_carries_yaw_and_shape_and_needs_them(tiny_baseline) -> None:
    env = ObjectModelEnv(tiny_baseline("in_full"))
    state = start_state(env)
    obs = observation(0)
    yaw = torch.from_numpy(obs["object_yaw"])
    assert state[OBJECT_FEAT].shape == (N, 10)
    torch.testing.assert_close(state[OBJECT_FEAT][:, :2], torch.stack([yaw.cos(), yaw.sin()], -1))
    with pytest.raises(KeyError, match="object_shape"):
        env.observe(
            torch.from_numpy(obs["pixels"]),
            torch.from_numpy(obs["object_pos"]),
            torch.from_numpy(obs["object_pos"]),
            object_yaw=yaw,
        )
    observed = METHODS["model_mpc"].observes
    assert OBJECT_YAW in observed and OBJECT_SHAPE in observed


def test_in_env_planning_improves_the_goal_reward_over_random_actions(tiny_baseline) -> None:
    """CEM finds pushes whose predicted reward beats the mean of random pushes."""
    env = ObjectModelEnv(tiny_baseline("in"))
    state = start_state(env)
    planner = GraphMPCPlanner(env, generator=torch.Generator().manual_seed(0), **PLANNER)
    planned = planner(state.clone())["action"]
    random_actions = torch.rand(64, 4, generator=torch.Generator().manual_seed(1)) * 2 - 1
    batch = state.expand(64).clone()
    batch["action"] = random_actions
    random_reward = env.step(batch)["next", "reward"].mean()
    single = state.clone()
    single["action"] = planned
    assert env.step(single)["next", "reward"].item() > random_reward.item()


@pytest.mark.parametrize("name", ["forw", "forwinv", "in", "in_full", "visin", "vcdn"])
def test_controller_acts_in_bounds_through_the_method_registry(name: str, tiny_baseline) -> None:
    settings = RearrangementSettings(methods=("model_mpc",), planner=PLANNER)
    context = MethodContext(tiny_baseline(name), SceneSettings(image_size=SIZE), settings, (0,))
    controller = METHODS["model_mpc"].make_controller(context)
    assert isinstance(controller, BaselineMPCController)
    goal = observation(1)
    controller.reset([SimpleNamespace(goal_pos=goal["object_pos"], goal_pixels=goal["pixels"])])
    action = controller.act([observation(0)])
    assert action.shape == (1, 4) and np.isfinite(action).all()
    assert np.abs(action).max() <= 1.0


def test_wrong_model_kinds_are_refused_with_a_clear_error(tiny_baseline, tmp_path) -> None:
    settings = RearrangementSettings(methods=("model_mpc",), planner=PLANNER)
    kinet_settings = RearrangementSettings(methods=("kinet_graph",), planner=PLANNER)
    with pytest.raises(TypeError, match="model_mpc"):
        evaluate_rearrangement(tiny_baseline("in"), kinet_settings, tmp_path / "unused")
    with pytest.raises(TypeError, match="kinet_graph"):
        make_baseline_env(torch.nn.Linear(2, 2))
    with pytest.raises(ValueError, match="need a model"):
        evaluate_rearrangement(None, settings, tmp_path / "unused")
    assert not (tmp_path / "unused").exists()  # refused before anything is written
    controller = BaselineMPCController(tiny_baseline("in"), PLANNER, (0,))
    with pytest.raises(RuntimeError, match="reset"):
        controller.act([observation(0)])
