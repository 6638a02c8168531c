"""The baselines' world models (``model.world_model()``), planning over them and the baseline MPC
method's controller (no simulation; tiny models)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import check_env_specs

from kinet_rl.envs import SceneSettings
from kinet_rl.keys import (
    ACTION,
    GOAL_IMAGE_FEAT,
    GOAL_KP_POS,
    GOAL_OBJECT_POS,
    GOAL_PIXELS,
    IMAGE_FEAT,
    KP_EDGE_TYPE,
    KP_POS,
    OBJECT_FEAT,
    OBJECT_POS,
    OBJECT_SHAPE,
    OBJECT_YAW,
    PIXELS,
)
from kinet_rl.pipeline import evaluate_rearrangement
from kinet_rl.planners import GraphMPCPlanner, PushWorldModel, PushWorldModelEnv
from kinet_rl.rearrangement.methods import METHODS, MethodContext
from kinet_rl.rearrangement.policies import PlannerPolicy
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


def observed(model, seed: int = 0) -> TensorDict:
    """What ``model`` observes of ``observation(seed)`` and its goal, ``observation(seed + 1)``."""
    obs, goal = observation(seed), observation(seed + 1)
    goals = {GOAL_PIXELS: goal["pixels"], GOAL_OBJECT_POS: goal["object_pos"]}
    entries = {key: torch.from_numpy(obs[key]) for key in model.capabilities.observes}
    entries.update({key: torch.from_numpy(goals[key]) for key in model.capabilities.goal})
    return TensorDict(entries, [])


def start_state(world_model: PushWorldModel, model, seed: int = 0) -> TensorDict:
    return world_model.observe(observed(model, seed))


STATE_KEYS = {
    "forw": [IMAGE_FEAT, GOAL_IMAGE_FEAT],
    "forwinv": [IMAGE_FEAT, GOAL_IMAGE_FEAT],
    "in": [OBJECT_POS, OBJECT_FEAT, GOAL_OBJECT_POS],
    "in_full": [OBJECT_POS, OBJECT_FEAT, GOAL_OBJECT_POS],
    "visin": [OBJECT_POS, OBJECT_FEAT, GOAL_OBJECT_POS],
    "vcdn": [KP_POS, KP_EDGE_TYPE, GOAL_KP_POS],
}
OBJECTIVE = {
    "forw": "feature_distance",
    "forwinv": "feature_distance",
    "in": "object_distance",
    "in_full": "object_distance",
    "visin": "object_distance",
    "vcdn": "keypoints_distance",
}


@pytest.mark.parametrize("name", ["forw", "forwinv", "in", "in_full", "visin", "vcdn"])
def test_world_model_env_specs_and_state_keys(name: str, tiny_baseline) -> None:
    model = tiny_baseline(name)
    assert model.planning.objective == OBJECTIVE[name]
    assert model.capabilities.objectives == (OBJECTIVE[name],)
    world_model = model.world_model()
    env = PushWorldModelEnv(world_model)
    state = start_state(world_model, model)
    keys = STATE_KEYS[name]
    assert set(keys) == set(world_model.state_shapes)
    assert set(keys) == set(env.observation_spec.keys(True, True))
    assert set(state.keys(True, True)) == set(keys)
    assert env.observation_spec.is_in(state)
    assert not env.batch_locked
    check_env_specs(env, tensordict=env.reset(state))


@pytest.mark.parametrize("name", ["forw", "in", "vcdn"])
def test_world_model_refuses_an_objective_it_does_not_declare(name: str, tiny_baseline) -> None:
    model = tiny_baseline(name)
    with pytest.raises(
        ValueError, match=f"cannot plan with the objective 'graph'.*{OBJECTIVE[name]}"
    ):
        model.world_model("graph")
    with pytest.raises(ValueError, match="Unknown planning objective 'nope'"):
        model.world_model("nope")


def test_object_reward_is_minus_mean_goal_distance_of_the_prediction(tiny_baseline) -> None:
    model = tiny_baseline("in")
    world_model = model.world_model()
    env = PushWorldModelEnv(world_model)
    state = start_state(world_model, model).expand(5).clone()
    state["action"] = torch.rand(5, 4) * 2 - 1
    out = env.step(state)
    pred = model.predict(state[OBJECT_POS], state[OBJECT_FEAT], state["action"])
    expected = -(pred - state[GOAL_OBJECT_POS]).norm(dim=-1).mean(-1, keepdim=True)
    torch.testing.assert_close(out["next", "reward"], expected)
    torch.testing.assert_close(out["next", OBJECT_POS], pred)
    torch.testing.assert_close(out["next", GOAL_OBJECT_POS], state[GOAL_OBJECT_POS])


def test_feature_reward_is_minus_squared_feature_distance(tiny_baseline) -> None:
    model = tiny_baseline("forw")
    world_model = model.world_model()
    env = PushWorldModelEnv(world_model)
    state = start_state(world_model, model).expand(5).clone()
    state["action"] = torch.rand(5, 4) * 2 - 1
    out = env.step(state)
    pred = model.predict(state[IMAGE_FEAT], state["action"])
    expected = -(pred - state[GOAL_IMAGE_FEAT]).pow(2).sum(-1, keepdim=True)
    torch.testing.assert_close(out["next", "reward"], expected)
    goal = torch.from_numpy(observation(1)["pixels"])
    torch.testing.assert_close(state[GOAL_IMAGE_FEAT][0], model.eval().encode(goal))


def test_visin_state_carries_crop_features_of_the_current_image(tiny_baseline) -> None:
    model = tiny_baseline("visin")
    world_model = model.world_model()
    a, b = start_state(world_model, model, 0), start_state(world_model, model, 5)
    assert a[OBJECT_FEAT].shape == (N, 4)
    assert not torch.allclose(a[OBJECT_FEAT], b[OBJECT_FEAT])
    state = a.clone().set(ACTION, torch.rand(4) * 2 - 1)
    out = PushWorldModelEnv(world_model).step(state)
    torch.testing.assert_close(out["next", OBJECT_FEAT], a[OBJECT_FEAT])  # carried over


def test_in_full_state_carries_yaw_and_shape_and_needs_them(tiny_baseline) -> None:
    model = tiny_baseline("in_full")
    world_model = model.world_model()
    state = start_state(world_model, model)
    yaw = torch.from_numpy(observation(0)["object_yaw"])
    assert state[OBJECT_FEAT].shape == (N, 10)
    torch.testing.assert_close(state[OBJECT_FEAT][:, :2], torch.stack([yaw.cos(), yaw.sin()], -1))
    assert model.capabilities.needs_ground_truth and not model.capabilities.plans_from_images
    observes = model.capabilities.observes
    assert OBJECT_YAW in observes and OBJECT_SHAPE in observes


def test_in_full_observe_names_a_missing_state_entry(tiny_baseline) -> None:
    model = tiny_baseline("in_full")
    with pytest.raises(KeyError, match="object_shape"):
        model.world_model().observe(observed(model).exclude(OBJECT_SHAPE))


@pytest.mark.parametrize("name", ["in", "in_full", "visin", "forw", "vcdn"])
def test_a_batch_is_observed_as_each_element_alone(name: str, tiny_baseline) -> None:
    model = tiny_baseline(name)
    world_model = model.world_model()
    batch = torch.stack([observed(model, 0), observed(model, 5)])
    together = world_model.observe(batch)
    assert together.batch_size == (2,)
    for i, seed in enumerate((0, 5)):
        alone = start_state(world_model, model, seed)
        for key in STATE_KEYS[name]:
            torch.testing.assert_close(together[i][key], alone[key], msg=str(key))


def test_in_planning_improves_the_goal_reward_over_random_actions(tiny_baseline) -> None:
    """CEM finds pushes whose predicted reward beats the mean of random pushes."""
    model = tiny_baseline("in")
    world_model = model.world_model()
    env = PushWorldModelEnv(world_model)
    state = start_state(world_model, model)
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
def test_policy_acts_in_bounds_through_the_method_registry(name: str, tiny_baseline) -> None:
    model = tiny_baseline(name)
    settings = RearrangementSettings(methods=("model_mpc",), planner=PLANNER)
    context = MethodContext(model, SceneSettings(image_size=SIZE), settings, (0,))
    policy = METHODS["model_mpc"].policy(context)
    assert isinstance(policy, PlannerPolicy)
    assert policy.push_planner.objective == OBJECTIVE[name]
    assert policy.in_keys == [*model.capabilities.observes, *model.capabilities.goal]
    policy.reset()
    action = policy(observed(model).unsqueeze(0))["action"]
    assert action.shape == (1, 4) and torch.isfinite(action).all()
    assert action.abs().max() <= 1.0
    state = policy.push_planner.last_state
    assert set(state.keys(True, True)) == set(STATE_KEYS[name])
    assert PIXELS not in state.keys(True, True)


def test_wrong_model_kinds_are_refused_with_a_clear_error(tiny_baseline, tmp_path) -> None:
    settings = RearrangementSettings(methods=("model_mpc",), planner=PLANNER)
    kinet_settings = RearrangementSettings(methods=("kinet_graph",), planner=PLANNER)
    with pytest.raises(ValueError, match="kinet_graph.*use method 'model_mpc'"):
        evaluate_rearrangement(tiny_baseline("in"), kinet_settings, tmp_path / "unused")
    with pytest.raises(ValueError, match="need a model"):
        evaluate_rearrangement(None, settings, tmp_path / "unused")
    assert not (tmp_path / "unused").exists()  # refused before anything is written
    context = MethodContext(tiny_baseline("in"), SceneSettings(image_size=SIZE), settings, (0,))
    policy = METHODS["model_mpc"].policy(context)
    with pytest.raises(KeyError, match="goal"):  # no goal in the tensordict
        policy(observed(tiny_baseline("in")).unsqueeze(0).exclude(("goal", "object_pos")))
