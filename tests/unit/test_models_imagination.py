"""Tests for KINet as a torchrl WorldModel (every keypoint objective) with a tiny untrained KINet."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.model_based import WorldModelEnv
from torchrl.envs.utils import check_env_specs
from torchrl.modules import WorldModel

from kinet_rl.keys import (
    ACTION,
    GOAL_KP_NODE_EMB,
    GOAL_KP_POS,
    GOAL_PIXELS,
    KP_FEAT,
    KP_POS,
    PIXELS,
)
from kinet_rl.models import KEYPOINT_OBJECTIVES, graph_similarity
from kinet_rl.planners import GraphMPCPlanner, PushWorldModelEnv, chamfer_distance


def observation(pixels, goal) -> TensorDict:
    """Current images ``[*B, H, W, 3]`` and a goal image for each (one ``[H, W, 3]`` for all)."""
    batch = pixels.shape[:-3]
    goal = goal.expand(*batch, *goal.shape[-3:]) if goal.dim() == 3 else goal
    return TensorDict({PIXELS: pixels, GOAL_PIXELS: goal}, batch_size=batch)


def test_encoder_builds_state_and_goal_graph(tiny_kinet, random_images) -> None:
    model = tiny_kinet()
    world_model = model.world_model()
    assert isinstance(world_model, WorldModel)
    pixels, goal = random_images((2,), 0), random_images((), 1)
    state = world_model.observe(observation(pixels, goal))
    assert state.batch_size == (2,)
    goal_pos, goal_feat = model.detector(goal)
    expected = model.interaction.embed_nodes(goal_pos, goal_feat)
    assert torch.allclose(state[GOAL_KP_NODE_EMB][1], expected, atol=1e-6)
    assert torch.allclose(state[GOAL_KP_POS][0], goal_pos, atol=1e-6)
    k, d = model.config["num_keypoints"], model.config["feat_dim"]
    assert state[KP_POS].shape == (2, k, 2) and state[KP_FEAT].shape == (2, k, d)
    env = PushWorldModelEnv(world_model)
    assert isinstance(env, WorldModelEnv)
    assert torch.equal(env.reset(state)[KP_POS], state[KP_POS])


def test_env_specs_pass_from_a_state(tiny_kinet, random_images) -> None:
    world_model = tiny_kinet().world_model()
    env = PushWorldModelEnv(world_model)
    state = world_model.observe(observation(random_images((), 0), random_images((), 1)))
    check_env_specs(env, tensordict=env.reset(state))


@pytest.mark.parametrize("objective", KEYPOINT_OBJECTIVES)
def test_step_reward_matches_the_definition(objective, tiny_kinet, random_images) -> None:
    model = tiny_kinet()
    world_model = model.world_model(objective)
    env = PushWorldModelEnv(world_model)
    state = world_model.observe(observation(random_images((3,), 0), random_images((), 1)))
    action = torch.rand(3, 4) * 2 - 1
    out = env.step(env.reset(state).set(ACTION, action))["next"]
    with torch.no_grad():
        pred = model.interaction(state[KP_POS], state[KP_FEAT], action)
        pred_nodes = model.interaction.embed_nodes(pred.next_pos, state[KP_FEAT])
    goal_nodes, goal_pos = state[GOAL_KP_NODE_EMB], state[GOAL_KP_POS]
    if objective == "graph":  # cosine of the flattened graphs
        a, b = pred.next_nodes.flatten(-2), goal_nodes.flatten(-2)
        expected = (a * b).sum(-1) / (a.norm(dim=-1) * b.norm(dim=-1))
    elif objective == "graph_dot":  # the paper's S / K
        expected = graph_similarity(pred.next_nodes, goal_nodes) / goal_nodes.shape[-2]
    elif objective == "graph_distance":
        expected = -(pred_nodes - goal_nodes).pow(2).sum(-1).mean(-1)
    elif objective == "keypoints_l2":  # keypoint k against goal keypoint k
        expected = -(pred.next_pos - goal_pos).norm(dim=-1).pow(2).mean(-1)
    elif objective == "keypoints_distance":
        expected = -(pred.next_pos - goal_pos).norm(dim=-1).mean(-1)
    else:
        expected = -chamfer_distance(pred.next_pos, goal_pos)
    assert torch.allclose(out["reward"], expected.unsqueeze(-1), atol=1e-5)
    assert torch.allclose(out[KP_POS], pred.next_pos, atol=1e-6)
    assert torch.equal(out[GOAL_KP_NODE_EMB], goal_nodes)  # goal carried along
    assert not out["done"].any()


@pytest.mark.parametrize("objective", KEYPOINT_OBJECTIVES)
def test_planner_finds_actions_the_model_scores_highly(objective, tiny_kinet, random_images):
    world_model = tiny_kinet().world_model(objective)
    env = PushWorldModelEnv(world_model)
    torch.manual_seed(0)
    planner = GraphMPCPlanner(env, planning_horizon=1, optim_steps=3, num_candidates=32, top_k=4)
    state = world_model.observe(observation(random_images((), 2), random_images((), 3)))
    action = planner(state.clone())[ACTION]
    assert env.action_spec.is_in(action)
    planned = env.step(state.clone().set(ACTION, action))["next", "reward"].item()
    randoms = torch.rand(128, 4) * 2 - 1
    batch = state.unsqueeze(0).expand(128).clone().set(ACTION, randoms)
    random_rewards = env.step(batch)["next", "reward"].squeeze(-1)
    assert planned >= torch.quantile(random_rewards, 0.9).item()


def test_bad_inputs_are_reported(tiny_kinet, random_images) -> None:
    world_model = tiny_kinet().world_model()
    with pytest.raises(ValueError, match="same"):
        world_model.observe(
            observation(random_images((), 0), torch.zeros(8, 8, 3, dtype=torch.uint8))
        )
    env = PushWorldModelEnv(world_model)
    with pytest.raises(KeyError, match="observe"):
        env.reset()
    with pytest.raises(KeyError, match="start state"):
        env.reset(TensorDict({PIXELS: random_images((), 0)}, []))  # not encoded
