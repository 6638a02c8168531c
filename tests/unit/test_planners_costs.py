"""Tests for the goal rewards and the GoalReward transform."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs import TransformedEnv
from torchrl.envs.utils import check_env_specs

from kinet_rl.keys import GOAL_KP_POS, KP_POS
from kinet_rl.planners import (
    GoalReward,
    GraphMPCPlanner,
    graph_similarity_reward,
    keypoint_goal_reward,
)
from toy_model_envs import QuadraticModelEnv


def test_keypoint_goal_reward_values() -> None:
    pos = torch.tensor([[[0.0, 0.0], [1.0, 1.0]]])  # [B=1, K=2, 2]
    goal = torch.tensor([[[3.0, 4.0], [1.0, 1.0]]])
    assert keypoint_goal_reward(pos, goal).tolist() == [[-25.0]]
    assert keypoint_goal_reward(goal, goal).tolist() == [[0.0]]


def test_graph_similarity_is_sum_of_node_dot_products() -> None:
    emb = torch.tensor([[1.0, 2.0], [0.0, 1.0]])  # [K=2, D=2]
    goal = torch.tensor([[3.0, 1.0], [5.0, -2.0]])
    assert graph_similarity_reward(emb, goal).tolist() == [5.0 - 2.0]


def test_reward_shape_mismatch_is_reported() -> None:
    with pytest.raises(ValueError, match="goal_pos"):
        keypoint_goal_reward(torch.zeros(3, 2), torch.zeros(4, 2))


def _goal_env(default_goal=None) -> TransformedEnv:
    base = QuadraticModelEnv(goal=torch.zeros(2, 2))  # base reward is overwritten
    return TransformedEnv(base, GoalReward(default_goal=default_goal))


def test_goal_reward_env_specs_and_reward_from_td_goal() -> None:
    env = _goal_env(default_goal=torch.ones(2, 2))
    check_env_specs(env)
    goal = torch.tensor([[1.0, 0.0], [0.0, -1.0]])
    td = env.reset(TensorDict({GOAL_KP_POS: goal}))
    assert torch.equal(td[GOAL_KP_POS], goal)
    td.set("action", torch.tensor([0.5, 0.0, 0.0, 0.0]))
    out = env.step(td)["next"]
    assert out["reward"].tolist() == [-(0.25 + 1.0)]
    assert torch.equal(out[GOAL_KP_POS], goal)


def test_missing_goal_is_reported() -> None:
    env = _goal_env()
    with pytest.raises(KeyError, match="default_goal"):
        env.reset()


def test_planner_reaches_per_element_goals_stored_in_td() -> None:
    torch.manual_seed(0)
    env = _goal_env()
    goals = torch.tensor([[[1.0, 1.0], [-1.0, 0.5]], [[-1.5, 0.0], [0.5, -1.0]]])  # [B=2, K, 2]
    planner = GraphMPCPlanner(env, planning_horizon=2, optim_steps=4, num_candidates=128, top_k=16)
    td = env.reset(TensorDict({GOAL_KP_POS: goals}, batch_size=[2]))
    initial = keypoint_goal_reward(td[KP_POS], goals)
    for _ in range(3):
        td = env.step_mdp(env.step(planner(td)))
    final = keypoint_goal_reward(td[KP_POS], goals)
    assert (final > initial / 50).all()  # squared distance cut by more than 50x per element
