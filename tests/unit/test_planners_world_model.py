"""PushWorldModel and PushWorldModelEnv: the world model of pushes every model builds and the
batch-less torchrl ``WorldModelEnv`` that GraphMPC and torchrl's CEM and MPPI planners plan over
(a toy world model: a point moved by the push, no ``kinet_rl.models``)."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torch import Tensor, nn
from torchrl.data import Bounded
from torchrl.envs.model_based import WorldModelEnv
from torchrl.envs.utils import check_env_specs
from torchrl.modules import ValueOperator, WorldModel
from torchrl.modules.planners import CEMPlanner, MPPIPlanner
from torchrl.objectives.value import TDLambdaEstimator

from kinet_rl.keys import ACTION, GOAL_KP_POS, KP_POS, PIXELS
from kinet_rl.planners import (
    VALIDATED_PLANNER,
    GraphMPCPlanner,
    PlanningDefaults,
    PushWorldModel,
    PushWorldModelEnv,
    goal_reward_head,
    push_dynamics,
)

POS, GOAL = KP_POS, GOAL_KP_POS
START = torch.zeros(1, 2)
TARGET = torch.tensor([[0.3, -0.2]])


class _Move(nn.Module):
    """A point ``[*B, 1, 2]`` moved by a tenth of the push's end minus its start."""

    def forward(self, pos: Tensor, action: Tensor) -> tuple[Tensor]:
        return (pos + 0.1 * (action[..., 2:] - action[..., :2]).unsqueeze(-2),)


class _Counted(nn.Module):
    """The identity encoder, counting its calls."""

    def __init__(self) -> None:
        super().__init__()
        self.calls = 0

    def forward(self, pos: Tensor) -> Tensor:
        self.calls += 1
        return pos


def make_world_model(objective: str = "keypoints_distance") -> PushWorldModel:
    """The point's world model: reward minus its distance to the goal (``keypoints_distance``)."""
    return PushWorldModel(
        TensorDictModule(_Counted(), in_keys=[POS], out_keys=[POS]),
        push_dynamics(_Move(), [POS, ACTION], [POS], [GOAL]),
        goal_reward_head(objective),
        {POS: (1, 2), GOAL: (1, 2)},
    )


def observation(batch: tuple[int, ...] = (), goal: Tensor = TARGET) -> TensorDict:
    return TensorDict(
        {
            POS: START.expand(*batch, 1, 2).clone(),
            GOAL: goal.expand(*batch, 1, 2).clone(),
            PIXELS: torch.zeros(*batch, 4, 4, 3, dtype=torch.uint8),  # not a state entry
        },
        batch,
    )


def test_specs_are_complete_and_the_env_is_batch_less_and_not_batch_locked() -> None:
    world_model = make_world_model()
    env = PushWorldModelEnv(world_model)
    assert isinstance(world_model, WorldModel) and isinstance(env, WorldModelEnv)
    assert env.world_model is world_model.step_module and env.latent_key == POS
    assert not env.batch_locked and env.batch_size == ()
    assert set(env.observation_spec.keys(True, True)) == {POS, GOAL}
    assert isinstance(env.action_spec, Bounded) and env.action_spec.shape == (4,)
    assert (env.action_spec.space.low == -1).all() and (env.action_spec.space.high == 1).all()
    assert env.reward_spec.shape == (1,)
    check_env_specs(env, tensordict=env.reset(world_model.observe(observation())))


def test_observe_runs_the_encoder_and_keeps_the_state_entries_only() -> None:
    world_model = make_world_model()
    obs = observation((3,))
    state = world_model.observe(obs)
    assert world_model.encoder.module.calls == 1
    assert state.batch_size == (3,)
    assert set(state.keys(True, True)) == {POS, GOAL}
    assert set(obs.keys(True, True)) == {POS, GOAL, PIXELS}  # the observation is left alone


def test_reset_without_a_start_state_names_it_and_how_to_build_it() -> None:
    env = PushWorldModelEnv(make_world_model())
    message = r"start state .*'pos'.*'goal'.*world_model\.observe\(observation\)"
    with pytest.raises(KeyError, match=message):
        env.reset()
    with pytest.raises(KeyError, match=message):
        env.reset(TensorDict({GOAL: TARGET}, []))


def test_reset_names_a_missing_goal() -> None:
    with pytest.raises(KeyError, match="goal"):
        PushWorldModelEnv(make_world_model()).reset(TensorDict({POS: START}, []))


@pytest.mark.parametrize("batch", [(), (3,), (2, 3)])
def test_reset_keeps_the_state_and_clears_done(batch: tuple[int, ...]) -> None:
    world_model = make_world_model()
    state = world_model.observe(observation(batch))
    td = PushWorldModelEnv(world_model).reset(state)
    assert td.batch_size == batch
    torch.testing.assert_close(td[POS], state[POS])
    torch.testing.assert_close(td[GOAL], state[GOAL])
    assert td["done"].shape == (*batch, 1) and not td["done"].any()
    assert not td["terminated"].any()


@pytest.mark.parametrize("batch", [(), (3,), (2, 3)])
def test_rollouts_at_any_batch_step_the_dynamics_not_the_encoder(batch: tuple[int, ...]) -> None:
    world_model = make_world_model()
    env = PushWorldModelEnv(world_model)
    state = world_model.observe(observation(batch))
    rollout = env.rollout(4, tensordict=env.reset(state))  # random pushes
    assert rollout.batch_size == (*batch, 4)
    assert world_model.encoder.module.calls == 1  # observe only
    action = rollout[ACTION]
    moved = rollout[POS] + 0.1 * (action[..., 2:] - action[..., :2]).unsqueeze(-2)
    torch.testing.assert_close(rollout["next", POS], moved)
    torch.testing.assert_close(rollout[POS][..., 1:, :, :], rollout["next", POS][..., :-1, :, :])
    reward = -(moved - TARGET).norm(dim=-1)  # keypoints_distance of one point
    torch.testing.assert_close(rollout["next", "reward"], reward)
    torch.testing.assert_close(rollout["next", GOAL], rollout[GOAL])  # the goal travels along
    assert not rollout["next", "done"].any() and not rollout["next", "terminated"].any()


def test_a_planner_moves_the_point_towards_the_goal() -> None:
    world_model = make_world_model()
    env = PushWorldModelEnv(world_model)
    planner = GraphMPCPlanner(
        env, planning_horizon=1, optim_steps=3, num_candidates=64, top_k=8,
        generator=torch.Generator().manual_seed(0),
    )  # fmt: skip
    state = world_model.observe(observation())
    before = (state[POS] - state[GOAL]).norm()
    for _ in range(5):
        action = planner(state.clone()).get(ACTION)
        state = env.step(state.clone().set(ACTION, action))["next"]
    assert (state[POS] - state[GOAL]).norm() < 0.3 * before


def test_the_planner_reaches_per_element_goals_stored_in_the_state() -> None:
    torch.manual_seed(0)
    world_model = make_world_model("keypoints_l2")
    env = PushWorldModelEnv(world_model)
    goals = torch.tensor([[[0.3, -0.2]], [[-0.25, 0.35]]])  # [B=2, K=1, 2]
    planner = GraphMPCPlanner(env, planning_horizon=2, optim_steps=4, num_candidates=128, top_k=16)
    td = env.reset(world_model.observe(observation((2,), goals)))
    initial = (td[POS] - goals).pow(2).sum((-2, -1))
    for _ in range(3):
        td = env.step_mdp(env.step(planner(td)))
    final = (td[POS] - goals).pow(2).sum((-2, -1))
    assert (final < initial / 50).all()  # squared distance cut by more than 50x per element


def _zero_value() -> ValueOperator:
    class Zero(nn.Module):
        def forward(self, pos: Tensor) -> Tensor:
            return pos.new_zeros(*pos.shape[:-2], 1)

    return ValueOperator(Zero(), in_keys=[POS])


@pytest.mark.parametrize("kind", ["cem", "mppi"])
def test_torchrl_planners_plan_over_it_at_any_batch(kind: str) -> None:
    torch.manual_seed(0)
    world_model = make_world_model()
    env = PushWorldModelEnv(world_model)
    budget = {"planning_horizon": 1, "optim_steps": 3, "num_candidates": 64, "top_k": 8}
    if kind == "cem":
        planner = CEMPlanner(env, **budget)
    else:
        advantage = TDLambdaEstimator(gamma=1.0, lmbda=1.0, value_network=_zero_value())
        planner = MPPIPlanner(env, advantage, temperature=1.0, **budget)
    for batch in [(), (3,)]:
        action = planner(env.reset(world_model.observe(observation(batch))))[ACTION]
        assert action.shape == (*batch, 4) and env.action_spec.is_in(action)
    state = env.reset(world_model.observe(observation()))
    rollout = env.rollout(3, planner, tensordict=state, auto_reset=False)
    final = (rollout["next", POS][-1] - TARGET).norm()
    assert final < 0.3 * TARGET.norm()


def test_planning_defaults_check_the_objective_and_round_trip() -> None:
    defaults = PlanningDefaults("graph_distance")
    assert dict(defaults.planner) == VALIDATED_PLANNER
    assert PlanningDefaults.from_mapping(defaults.as_dict()) == defaults
    with pytest.raises(ValueError, match="Unknown planning objective 'nope'"):
        PlanningDefaults("nope")
