"""StateModelEnv: the shared base of every model env (specs, reset, planning through it)."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.envs.utils import check_env_specs

from kinet_rl.keys import ACTION, STEP_REWARD
from kinet_rl.planners import GraphMPCPlanner, StateModelEnv

POS, GOAL = ("point", "pos"), ("goal", "point", "pos")


class _Move(nn.Module):
    """A point moved by the push's end minus its start; reward: minus the distance to the goal."""

    def forward(self, pos, action, goal):
        nxt = pos + 0.1 * (action[..., 2:] - action[..., :2])
        return nxt, -(nxt - goal).norm(dim=-1, keepdim=True), goal


def make_env() -> StateModelEnv:
    step = TensorDictModule(_Move(), [POS, ACTION, GOAL], [POS, STEP_REWARD, GOAL])
    return StateModelEnv(step, {POS: (2,), GOAL: (2,)}, reset_hint="give a point and a goal.")


def start() -> TensorDict:
    return TensorDict({POS: torch.zeros(2), GOAL: torch.tensor([0.3, -0.2])}, [])


def test_specs_are_complete_and_the_env_is_not_batch_locked():
    env = make_env()
    assert not env.batch_locked
    check_env_specs(env, tensordict=env.reset(start()))


def test_reset_names_the_missing_state_and_the_hint():
    with pytest.raises(KeyError, match="state keys .*goal.*give a point and a goal"):
        make_env().reset(TensorDict({POS: torch.zeros(2)}, []))


def test_a_planner_moves_the_point_towards_the_goal():
    env = make_env()
    planner = GraphMPCPlanner(
        env, planning_horizon=1, optim_steps=3, num_candidates=64, top_k=8,
        generator=torch.Generator().manual_seed(0),
    )  # fmt: skip
    state = start()
    before = (state[POS] - state[GOAL]).norm()
    for _ in range(5):
        action = planner(state.clone()).get(ACTION)
        state = env.step(state.clone().set(ACTION, action))["next"]
    assert (state[POS] - state[GOAL]).norm() < 0.3 * before
