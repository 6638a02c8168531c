"""Tests for KINetModelEnv (graph and keypoint rewards) with a tiny untrained KINet."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import check_env_specs

from kinet_rl.control import KINetModelEnv, chamfer_distance, make_kinet_planner
from kinet_rl.keys import ACTION, GOAL_KP_NODE_EMB, GOAL_KP_POS, KP_FEAT, KP_POS, PIXELS
from kinet_rl.models import KINetWorldModel, graph_similarity

K = 4


def tiny_model(seed: int = 0) -> KINetWorldModel:
    torch.manual_seed(seed)
    model = KINetWorldModel(
        num_keypoints=K,
        feat_dim=4,
        channels=8,
        embed_dim=8,
        hidden_dim=16,
        num_hidden=1,
        num_rounds=1,
    )
    return model.eval()


def images(batch: tuple[int, ...], seed: int) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    return torch.randint(0, 256, (*batch, 16, 16, 3), generator=gen, dtype=torch.uint8)


def test_chamfer_distance_values_and_permutation_invariance() -> None:
    a = torch.tensor([[0.0, 0.0], [1.0, 0.0]])
    assert chamfer_distance(a, a.flip(0)).item() == 0.0
    b = torch.tensor([[0.0, 0.5], [1.0, 0.0]])
    assert chamfer_distance(a, b).item() == pytest.approx(0.25)  # 0.5 of 2 points, both ways


def test_observe_builds_state_and_goal_graph() -> None:
    model = tiny_model()
    env = KINetModelEnv(model)
    pixels, goal = images((2,), 0), images((), 1)
    state = env.observe(pixels, goal)
    assert state.batch_size == (2,)
    goal_pos, goal_feat = model.detector(goal)
    expected = model.interaction.embed_nodes(goal_pos, goal_feat)
    assert torch.allclose(state[GOAL_KP_NODE_EMB][1], expected, atol=1e-6)
    assert torch.allclose(state[GOAL_KP_POS][0], goal_pos, atol=1e-6)
    assert state[KP_POS].shape == (2, K, 2) and state[KP_FEAT].shape == (2, K, 4)
    reset_input = TensorDict({PIXELS: pixels, ("goal", PIXELS): goal.expand(2, 16, 16, 3)}, [2])
    assert torch.equal(env.reset(reset_input)[KP_POS], state[KP_POS])


def test_env_specs_pass_from_a_state() -> None:
    env = KINetModelEnv(tiny_model())
    check_env_specs(env, tensordict=env.reset(env.observe(images((), 0), images((), 1))))


@pytest.mark.parametrize("reward", ["graph", "graph_distance", "keypoints"])
def test_step_reward_matches_the_definition(reward: str) -> None:
    model = tiny_model()
    env = KINetModelEnv(model, reward=reward)
    state = env.observe(images((3,), 0), images((), 1))
    action = torch.rand(3, 4) * 2 - 1
    out = env.step(state.clone().set(ACTION, action))["next"]
    with torch.no_grad():
        pred = model.interaction(state[KP_POS], state[KP_FEAT], action)
        pred_nodes = model.interaction.embed_nodes(pred.next_pos, state[KP_FEAT])
    if reward == "graph":
        expected = graph_similarity(pred.next_nodes, state[GOAL_KP_NODE_EMB]) / K
    elif reward == "graph_distance":
        expected = -(pred_nodes - state[GOAL_KP_NODE_EMB]).pow(2).sum(-1).mean(-1)
    else:
        expected = -chamfer_distance(pred.next_pos, state[GOAL_KP_POS])
    assert torch.allclose(out["reward"], expected.unsqueeze(-1), atol=1e-5)
    assert torch.allclose(out[KP_POS], pred.next_pos, atol=1e-6)
    assert torch.equal(out[GOAL_KP_NODE_EMB], state[GOAL_KP_NODE_EMB])  # goal carried along


@pytest.mark.parametrize("reward", ["graph", "graph_distance", "keypoints"])
def test_planner_finds_actions_the_model_scores_highly(reward: str) -> None:
    model = tiny_model()
    torch.manual_seed(0)
    planner = make_kinet_planner(
        model, reward=reward, planning_horizon=1, optim_steps=3, num_candidates=32, top_k=4
    )
    env = planner.env
    state = env.observe(images((), 2), images((), 3))
    action = planner(state.clone())[ACTION]
    assert env.action_spec.is_in(action)
    planned = env.step(state.clone().set(ACTION, action))["next", "reward"].item()
    randoms = torch.rand(128, 4) * 2 - 1
    batch = state.unsqueeze(0).expand(128).clone().set(ACTION, randoms)
    random_rewards = env.step(batch)["next", "reward"].squeeze(-1)
    assert planned >= torch.quantile(random_rewards, 0.9).item()


def test_bad_inputs_are_reported() -> None:
    env = KINetModelEnv(tiny_model())
    with pytest.raises(ValueError, match="reward"):
        KINetModelEnv(tiny_model(), reward="pixels")
    with pytest.raises(ValueError, match="same"):
        env.observe(images((), 0), torch.zeros(8, 8, 3, dtype=torch.uint8))
    with pytest.raises(KeyError, match="observe"):
        env.reset()
