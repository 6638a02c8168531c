"""Planning with less arithmetic: the fast path against the straightforward computation."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from kinet_rl.keys import (
    ACTION,
    GOAL_KP_NODE_EMB,
    GOAL_KP_POS,
    GOAL_PIXELS,
    KP_FEAT,
    KP_POS,
    PIXELS,
)
from kinet_rl.models import KINetWorldModel
from kinet_rl.planners import GraphMPCPlanner, PushWorldModelEnv

CANDIDATES = 16
PREDICTION_FIELDS = ("next_pos", "next_nodes", "nodes", "edge_prob", "kl")


@pytest.fixture
def small_kinet(tiny_kinet):
    """A tiny KINet with K keypoints, two rounds and the learnt action frame."""

    def make(num_keypoints: int, deterministic: bool = False) -> KINetWorldModel:
        return tiny_kinet(
            num_keypoints=num_keypoints,
            num_rounds=2,
            deterministic=deterministic,
            action_frame="learned",
        )

    return make


def start_state(model: KINetWorldModel) -> TensorDict:
    cfg = model.config
    k, d, e = cfg["num_keypoints"], cfg["feat_dim"], cfg["embed_dim"]
    gen = torch.Generator().manual_seed(1)
    return TensorDict(
        {
            KP_POS: torch.rand(k, 2, generator=gen) * 2 - 1,
            KP_FEAT: torch.randn(k, d, generator=gen),
            GOAL_KP_NODE_EMB: torch.randn(k, e, generator=gen),
            GOAL_KP_POS: torch.rand(k, 2, generator=gen) * 2 - 1,
        },
        batch_size=[],
    )


@pytest.mark.parametrize("deterministic", [False, True])
@pytest.mark.parametrize("training", [False, True])
@pytest.mark.parametrize("k", [6, 9])
def test_one_start_graph_for_all_pushes_predicts_what_each_copy_does(
    k, training, deterministic, small_kinet
):
    net = small_kinet(k, deterministic).interaction.train(training)
    gen = torch.Generator().manual_seed(2)
    pos, feat = torch.rand(2, 1, k, 2, generator=gen), torch.randn(2, 1, k, 4, generator=gen)
    action = torch.rand(2, CANDIDATES, 4, generator=gen) * 2 - 1
    copies = (pos.expand(2, CANDIDATES, k, 2).clone(), feat.expand(2, CANDIDATES, k, 4).clone())
    torch.manual_seed(3)  # same edge samples in training
    reference = net(*copies, action, fast=False)
    torch.manual_seed(3)
    fast = net(pos, feat, action)
    for field in PREDICTION_FIELDS:
        expected = getattr(reference, field)
        assert getattr(fast, field).shape == expected.shape == (2, CANDIDATES, *expected.shape[2:])
        torch.testing.assert_close(getattr(fast, field), expected, msg=field)
    if training and not deterministic:  # the candidates' edges were sampled independently
        assert not torch.allclose(fast.edge_prob[:, 0], fast.edge_prob[:, 1])


@pytest.mark.parametrize("training", [False, True])
@pytest.mark.parametrize("horizon", [1, 3])
@pytest.mark.parametrize("k", [6, 9])
def test_fast_rollouts_return_what_the_straightforward_ones_do(k, horizon, training, small_kinet):
    model = small_kinet(k).train(training)
    state = start_state(model)
    start = state.unsqueeze(-1).expand(CANDIDATES)  # as GraphMPCPlanner passes it
    actions = torch.rand(CANDIDATES, horizon, 4, generator=torch.Generator().manual_seed(4))
    returns = {}
    for fast in (True, False):
        env = PushWorldModelEnv(model.world_model("graph_distance", fast=fast))
        planner = GraphMPCPlanner(env, planning_horizon=horizon, num_candidates=CANDIDATES, top_k=4)
        torch.manual_seed(5)  # same edge samples in training
        with torch.no_grad():
            returns[fast] = planner.rollout_returns(start, actions)
    torch.testing.assert_close(returns[True], returns[False])
    assert returns[True].std() > 0  # the candidates' pushes matter


def test_the_start_graph_is_encoded_once_for_all_candidates(small_kinet):
    model = small_kinet(6)
    encoded_rows: list[int] = []
    model.interaction.node_encoder.register_forward_hook(
        lambda module, inputs, output: encoded_rows.append(inputs[0].shape[:-1].numel())
    )
    env = PushWorldModelEnv(model.world_model("graph"))
    planner = GraphMPCPlanner(
        env, planning_horizon=2, optim_steps=1, num_candidates=CANDIDATES, top_k=4
    )
    planner(start_state(model))
    # step 1 from the shared start, step 2 from each candidate's own prediction, then the reward
    assert encoded_rows[:2] == [6, 6 * CANDIDATES]


def test_same_seed_plans_the_same_push_fast_or_not(small_kinet):
    model = small_kinet(6)
    pushes = []
    for fast in (True, False):
        env = PushWorldModelEnv(model.world_model("graph", fast=fast))
        generator = torch.Generator().manual_seed(6)
        planner = GraphMPCPlanner(env, planning_horizon=3, optim_steps=3, generator=generator)
        pushes.append(planner(start_state(model))[ACTION])
    assert not torch.allclose(pushes[0], torch.zeros(4))
    torch.testing.assert_close(pushes[0], pushes[1])


def test_the_goal_graph_is_computed_once_per_goal_image_and_model(small_kinet, random_images):
    model = small_kinet(4)
    fast, reference = model.world_model(), model.world_model(fast=False)

    def observe(world_model, pixels, goal):
        goal = goal.expand(*pixels.shape[:-3], *goal.shape)
        return world_model.observe(TensorDict({PIXELS: pixels, GOAL_PIXELS: goal}, [2]))

    goal, other_goal = random_images((), 1), random_images((), 2)
    expected = observe(reference, random_images((2,), 0), other_goal)
    goal_images: list[torch.Tensor] = []
    model.interaction.node_encoder.register_forward_hook(
        lambda module, inputs, output: goal_images.append(inputs[0])
    )
    for step in range(3):
        observe(fast, random_images((2,), 10 + step), goal.clone())  # a new tensor every call
    assert len(goal_images) == 1
    state = observe(fast, random_images((2,), 0), other_goal)
    assert len(goal_images) == 2  # a new goal image is embedded
    for key in (GOAL_KP_NODE_EMB, GOAL_KP_POS, KP_POS, KP_FEAT):
        torch.testing.assert_close(state[key], expected[key])
    with torch.no_grad():
        model.interaction.node_encoder[0].bias.add_(1.0)  # e.g. a training step
    changed = observe(fast, random_images((2,), 0), other_goal)
    assert len(goal_images) == 3  # new weights, new embeddings
    assert not torch.allclose(changed[GOAL_KP_NODE_EMB], state[GOAL_KP_NODE_EMB])
