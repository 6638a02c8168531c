"""Tests for the analytic push model and the oracle's world model."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import check_env_specs

from kinet_rl.baselines import AnalyticPushModel, analytic_push
from kinet_rl.keys import GOAL_OBJECT_POS, OBJECT_POS
from kinet_rl.planners import GraphMPCPlanner, PlanningInterface, PushWorldModelEnv

HALF = 0.2
R = 0.03


def test_push_moves_only_objects_on_its_path_to_just_past_the_end() -> None:
    objects = torch.tensor(
        [[0.0, 0.0], [0.0, 0.1], [-0.1, 0.0], [0.0, 0.02]]  # on path, aside, behind, off-centre
    )
    action = torch.tensor([-0.25, 0.0, 0.25, 0.0])  # from x=-0.05 m to x=+0.05 m
    moved = analytic_push(objects, action, HALF, R)
    assert moved[0].tolist() == pytest.approx([0.05 + R, 0.0])
    assert torch.equal(moved[1], objects[1]) and torch.equal(moved[2], objects[2])
    lateral_end = 0.05 + (R**2 - 0.02**2) ** 0.5
    assert moved[3].tolist() == pytest.approx([lateral_end, 0.02])


def test_oracle_declares_what_it_plans_with() -> None:
    model = AnalyticPushModel(2, HALF, R)
    assert isinstance(model, PlanningInterface)
    assert model.planning.objective == "object_distance"
    assert model.capabilities.observes == (OBJECT_POS,)
    assert model.capabilities.goal == (GOAL_OBJECT_POS,)
    assert model.capabilities.needs_ground_truth
    with pytest.raises(ValueError, match="Oracle cannot plan with the objective 'keypoints'"):
        model.world_model("keypoints")


def test_oracle_env_specs_and_reward() -> None:
    world_model = AnalyticPushModel(2, HALF, R).world_model()
    env = PushWorldModelEnv(world_model)
    observation = TensorDict(
        {OBJECT_POS: torch.tensor([[0.0, 0.0], [0.1, 0.1]]), GOAL_OBJECT_POS: torch.zeros(2, 2)}, []
    )
    start = world_model.observe(observation)
    assert set(start.keys(True, True)) == {OBJECT_POS, GOAL_OBJECT_POS}
    check_env_specs(env, tensordict=env.reset(start))
    out = env.step(env.reset(start).set("action", torch.zeros(4)))["next"]  # zero-length push
    assert out["reward"].item() == pytest.approx(-(0.1 * 2**0.5) / 2)
    with pytest.raises(KeyError, match=r"start state .*'object_pos'.*\('goal', 'object_pos'\)"):
        env.reset()
    with pytest.raises(KeyError, match="object_pos"):
        env.reset(start.exclude(OBJECT_POS))


def test_oracle_env_reset_names_a_missing_goal() -> None:
    env = PushWorldModelEnv(AnalyticPushModel(2, HALF, R).world_model())
    start = TensorDict({OBJECT_POS: torch.zeros(2, 2)}, [])
    with pytest.raises(KeyError, match=r"\('goal', 'object_pos'\)"):
        env.reset(start)


def test_oracle_reward_matches_the_analytic_push_at_any_batch() -> None:
    env = PushWorldModelEnv(AnalyticPushModel(2, HALF, R).world_model())
    gen = torch.Generator().manual_seed(0)
    pos = torch.rand(3, 5, 2, 2, generator=gen) * 0.2 - 0.1
    goal = torch.rand(3, 5, 2, 2, generator=gen) * 0.2 - 0.1
    action = torch.rand(3, 5, 4, generator=gen) * 2 - 1
    start = TensorDict({OBJECT_POS: pos, GOAL_OBJECT_POS: goal}, [3, 5])
    out = env.step(env.reset(start).set("action", action))["next"]
    moved = analytic_push(pos, action, HALF, R)
    torch.testing.assert_close(out[OBJECT_POS], moved)
    expected = -(moved - goal).norm(dim=-1).mean(-1, keepdim=True)
    torch.testing.assert_close(out["reward"], expected)


def test_oracle_planner_brings_objects_to_the_goal_in_the_model() -> None:
    torch.manual_seed(0)
    world_model = AnalyticPushModel(2, HALF, R).world_model()
    env = PushWorldModelEnv(world_model)
    planner = GraphMPCPlanner(env, planning_horizon=1, optim_steps=5, num_candidates=256, top_k=16)
    goal = torch.tensor([[0.1, 0.0], [-0.05, -0.1]])
    td = env.reset(
        world_model.observe(
            TensorDict(
                {OBJECT_POS: torch.tensor([[0.0, 0.0], [-0.05, 0.05]]), GOAL_OBJECT_POS: goal}, []
            )
        )
    )
    start = (td[OBJECT_POS] - goal).norm(dim=-1).mean().item()
    for _ in range(4):
        td = env.step_mdp(env.step(planner(td)))
    final = (td[OBJECT_POS] - goal).norm(dim=-1).mean().item()
    assert final < start / 4
