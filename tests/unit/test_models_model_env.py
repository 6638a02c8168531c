"""Tests for KINetModelEnv (graph and keypoint rewards) with a tiny untrained KINet."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import check_env_specs

from kinet_rl.keys import (
    ACTION,
    GOAL_KP_NODE_EMB,
    GOAL_KP_POS,
    GOAL_PIXELS,
    KP_FEAT,
    KP_POS,
    PIXELS,
)
from kinet_rl.models import (
    REWARDS,
    GraphDistanceReward,
    GraphSimilarityReward,
    KeypointChamferReward,
    KeypointDistanceReward,
    KeypointL2Reward,
    KINetModelEnv,
    chamfer_distance,
    graph_similarity,
)
from kinet_rl.planners import GraphMPCPlanner, StateModelEnv

REWARD_CLASSES = [
    GraphSimilarityReward,
    GraphDistanceReward,
    KeypointChamferReward,
    KeypointL2Reward,
    KeypointDistanceReward,
]


def test_chamfer_distance_values_and_permutation_invariance() -> None:
    a = torch.tensor([[0.0, 0.0], [1.0, 0.0]])
    assert chamfer_distance(a, a.flip(0)).item() == 0.0
    b = torch.tensor([[0.0, 0.5], [1.0, 0.0]])
    assert chamfer_distance(a, b).item() == pytest.approx(0.25)  # 0.5 of 2 points, both ways


def test_rewards_by_command_line_name() -> None:
    assert {
        "graph": GraphSimilarityReward,
        "graph_distance": GraphDistanceReward,
        "keypoints": KeypointChamferReward,
        "keypoints_l2": KeypointL2Reward,
        "keypoints_distance": KeypointDistanceReward,
    } == REWARDS


def test_observe_builds_state_and_goal_graph(tiny_kinet, random_images) -> None:
    model = tiny_kinet()
    env = KINetModelEnv(model)
    assert isinstance(env, StateModelEnv) and isinstance(env.reward, GraphSimilarityReward)
    pixels, goal = random_images((2,), 0), random_images((), 1)
    state = env.observe(pixels, goal)
    assert state.batch_size == (2,)
    goal_pos, goal_feat = model.detector(goal)
    expected = model.interaction.embed_nodes(goal_pos, goal_feat)
    assert torch.allclose(state[GOAL_KP_NODE_EMB][1], expected, atol=1e-6)
    assert torch.allclose(state[GOAL_KP_POS][0], goal_pos, atol=1e-6)
    k, d = model.config["num_keypoints"], model.config["feat_dim"]
    assert state[KP_POS].shape == (2, k, 2) and state[KP_FEAT].shape == (2, k, d)
    reset_input = TensorDict({PIXELS: pixels, GOAL_PIXELS: goal.expand(2, 16, 16, 3)}, [2])
    assert torch.equal(env.reset(reset_input)[KP_POS], state[KP_POS])


def test_env_specs_pass_from_a_state(tiny_kinet, random_images) -> None:
    env = KINetModelEnv(tiny_kinet())
    check_env_specs(
        env, tensordict=env.reset(env.observe(random_images((), 0), random_images((), 1)))
    )


@pytest.mark.parametrize("reward", REWARD_CLASSES)
def test_step_reward_matches_the_definition(reward, tiny_kinet, random_images) -> None:
    model = tiny_kinet()
    env = KINetModelEnv(model, reward=reward())
    state = env.observe(random_images((3,), 0), random_images((), 1))
    action = torch.rand(3, 4) * 2 - 1
    out = env.step(state.clone().set(ACTION, action))["next"]
    with torch.no_grad():
        pred = model.interaction(state[KP_POS], state[KP_FEAT], action)
        pred_nodes = model.interaction.embed_nodes(pred.next_pos, state[KP_FEAT])
    if reward is GraphSimilarityReward:  # cosine of the flattened graphs (the default)
        a, b = pred.next_nodes.flatten(-2), state[GOAL_KP_NODE_EMB].flatten(-2)
        expected = (a * b).sum(-1) / (a.norm(dim=-1) * b.norm(dim=-1))
    elif reward is GraphDistanceReward:
        expected = -(pred_nodes - state[GOAL_KP_NODE_EMB]).pow(2).sum(-1).mean(-1)
    elif reward is KeypointL2Reward:  # keypoint k against goal keypoint k
        expected = -(pred.next_pos - state[GOAL_KP_POS]).norm(dim=-1).pow(2).mean(-1)
    elif reward is KeypointDistanceReward:
        expected = -(pred.next_pos - state[GOAL_KP_POS]).norm(dim=-1).mean(-1)
    else:
        expected = -chamfer_distance(pred.next_pos, state[GOAL_KP_POS])
    assert torch.allclose(out["reward"], expected.unsqueeze(-1), atol=1e-5)
    assert torch.allclose(out[KP_POS], pred.next_pos, atol=1e-6)
    assert torch.equal(out[GOAL_KP_NODE_EMB], state[GOAL_KP_NODE_EMB])  # goal carried along


def test_the_papers_dot_product_similarity_is_available(tiny_kinet, random_images) -> None:
    model = tiny_kinet()
    env = KINetModelEnv(model, reward=GraphSimilarityReward("dot"))
    state = env.observe(random_images((3,), 0), random_images((), 1))
    action = torch.rand(3, 4) * 2 - 1
    out = env.step(state.clone().set(ACTION, action))["next"]
    with torch.no_grad():
        pred = model.interaction(state[KP_POS], state[KP_FEAT], action)
    k = model.config["num_keypoints"]
    expected = graph_similarity(pred.next_nodes, state[GOAL_KP_NODE_EMB]) / k
    assert torch.allclose(out["reward"], expected.unsqueeze(-1), atol=1e-5)
    with pytest.raises(ValueError, match="similarity='l1'"):
        GraphSimilarityReward("l1")


@pytest.mark.parametrize("reward", REWARD_CLASSES)
def test_planner_finds_actions_the_model_scores_highly(reward, tiny_kinet, random_images) -> None:
    model = tiny_kinet()
    torch.manual_seed(0)
    env = KINetModelEnv(model.eval(), reward())
    planner = GraphMPCPlanner(env, planning_horizon=1, optim_steps=3, num_candidates=32, top_k=4)
    state = env.observe(random_images((), 2), random_images((), 3))
    action = planner(state.clone())[ACTION]
    assert env.action_spec.is_in(action)
    planned = env.step(state.clone().set(ACTION, action))["next", "reward"].item()
    randoms = torch.rand(128, 4) * 2 - 1
    batch = state.unsqueeze(0).expand(128).clone().set(ACTION, randoms)
    random_rewards = env.step(batch)["next", "reward"].squeeze(-1)
    assert planned >= torch.quantile(random_rewards, 0.9).item()


def test_bad_inputs_are_reported(tiny_kinet, random_images) -> None:
    env = KINetModelEnv(tiny_kinet())
    with pytest.raises(ValueError, match="same"):
        env.observe(random_images((), 0), torch.zeros(8, 8, 3, dtype=torch.uint8))
    with pytest.raises(KeyError, match="observe"):
        env.reset()
    with pytest.raises(KeyError, match="KINetModelEnv.reset needs .* state keys"):
        env.reset(TensorDict({PIXELS: random_images((), 0)}, []))  # no goal image
    with pytest.raises(TypeError, match="KINetReward object.*GraphDistanceReward"):
        KINetModelEnv(tiny_kinet(), reward="graph")
