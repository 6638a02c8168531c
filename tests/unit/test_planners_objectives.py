"""The planning objectives (``OBJECTIVES``): each formula against a hand computation, the registry,
and the reward head of a world model (``goal_reward_head``)."""

from __future__ import annotations

import math

import pytest
import torch
from tensordict import TensorDict

from kinet_rl.keys import (
    GOAL_IMAGE_FEAT,
    GOAL_KP_NODE_EMB,
    GOAL_KP_POS,
    GOAL_OBJECT_POS,
    IMAGE_FEAT,
    KP_NODE_EMB,
    KP_POS,
    KP_POS_EMB,
    OBJECT_POS,
    REWARD,
)
from kinet_rl.models import graph_similarity  # the paper's S = sum_k n_k . g_k
from kinet_rl.planners import (
    OBJECTIVES,
    GoalObjective,
    chamfer_distance,
    goal_objective,
    goal_reward_head,
)

# Two points or node embeddings [K=2, 2] and their goal [2, 2].
STATE = torch.tensor([[1.0, 2.0], [0.0, 1.0]])
GOAL = torch.tensor([[3.0, 1.0], [5.0, -2.0]])
# |state_k - goal_k|^2: (-2, 1) -> 5 and (-5, 3) -> 34.
SQUARED = (5.0, 34.0)

#: name -> (state key, goal key, state, goal, the score computed by hand).
HAND: dict[str, tuple] = {
    # cosine of the flattened graphs: (3 + 2 + 0 - 2) / (|(1, 2, 0, 1)| |(3, 1, 5, -2)|)
    "graph": (KP_NODE_EMB, GOAL_KP_NODE_EMB, STATE, GOAL, 3.0 / (math.sqrt(6) * math.sqrt(39))),
    # (1/K) sum_k n_k . g_k = ((3 + 2) + (0 - 2)) / 2
    "graph_dot": (KP_NODE_EMB, GOAL_KP_NODE_EMB, STATE, GOAL, 1.5),
    # -(1/K) sum_k |n_k - g_k|^2, n = embeddings of the predicted keypoints
    "graph_distance": (KP_POS_EMB, GOAL_KP_NODE_EMB, STATE, GOAL, -sum(SQUARED) / 2),
    # Chamfer: (0,0)->(0,0) 0, (1,0)->(0,0) 1; (0,0) 0, (0,2)->(0,0) 2, (3,0)->(1,0) 2:
    # -0.5 * (mean(0, 1) + mean(0, 2, 2))
    "keypoints": (
        KP_POS,
        GOAL_KP_POS,
        torch.tensor([[0.0, 0.0], [1.0, 0.0]]),
        torch.tensor([[0.0, 0.0], [0.0, 2.0], [3.0, 0.0]]),
        -0.5 * (0.5 + 4.0 / 3.0),
    ),
    # -(1/K) sum_k |x_k - g_k|^2
    "keypoints_l2": (KP_POS, GOAL_KP_POS, STATE, GOAL, -sum(SQUARED) / 2),
    # -(1/K) sum_k |x_k - g_k|
    "keypoints_distance": (
        KP_POS,
        GOAL_KP_POS,
        STATE,
        GOAL,
        -sum(math.sqrt(s) for s in SQUARED) / 2,
    ),
    # -(1/N) sum_n |p_n - g_n| in metres: (0, 0) and (0.1, 0.1) against the origin
    "object_distance": (
        OBJECT_POS,
        GOAL_OBJECT_POS,
        torch.tensor([[0.0, 0.0], [0.1, 0.1]]),
        torch.zeros(2, 2),
        -(0.1 * math.sqrt(2)) / 2,
    ),
    # -|z - z_goal|^2 = -(1 + 4 + 4)
    "feature_distance": (
        IMAGE_FEAT,
        GOAL_IMAGE_FEAT,
        torch.tensor([1.0, 2.0, 3.0]),
        torch.tensor([0.0, 0.0, 1.0]),
        -9.0,
    ),
}


def test_every_objective_is_checked_by_hand() -> None:
    assert set(OBJECTIVES) == set(HAND)
    for name, objective in OBJECTIVES.items():
        assert objective.name == name and objective.label


@pytest.mark.parametrize("name", sorted(HAND))
def test_objective_formula_and_keys(name: str) -> None:
    state_key, goal_key, state, goal, expected = HAND[name]
    objective = goal_objective(name)
    assert (objective.state_key, objective.goal_key) == (state_key, goal_key)
    score = objective.score(state, goal)
    assert score.shape == ()
    assert score.item() == pytest.approx(expected, rel=1e-6)
    at_goal = {"graph": 1.0, "graph_dot": (GOAL * GOAL).sum().item() / 2}.get(name, 0.0)
    assert objective.score(goal, goal).item() == pytest.approx(at_goal)  # distances: 0 at the goal


@pytest.mark.parametrize("name", sorted(HAND))
def test_objective_scores_a_batch_as_each_element(name: str) -> None:
    _, _, state, goal, _ = HAND[name]
    gen = torch.Generator().manual_seed(0)
    states = state + torch.randn(2, 3, *state.shape, generator=gen)
    goals = goal + torch.randn(2, 3, *goal.shape, generator=gen)
    score = goal_objective(name).score(states, goals)
    assert score.shape == (2, 3)
    for i in range(2):
        for j in range(3):
            alone = goal_objective(name).score(states[i, j], goals[i, j])
            torch.testing.assert_close(score[i, j], alone)


def test_graph_dot_is_paper_s_over_k() -> None:
    score = goal_objective("graph_dot").score(STATE, GOAL)
    torch.testing.assert_close(score, graph_similarity(STATE, GOAL) / STATE.shape[-2])


def test_chamfer_distance_needs_no_correspondence_and_broadcasts_the_goal() -> None:
    pos = torch.tensor([[0.0, 0.0], [1.0, 0.0]])
    goal = torch.tensor([[0.0, 0.0], [0.0, 2.0], [3.0, 0.0]])
    assert chamfer_distance(pos, goal).item() == pytest.approx(0.5 * (0.5 + 4.0 / 3.0))
    assert chamfer_distance(pos.flip(0), goal.flip(0)).item() == pytest.approx(
        chamfer_distance(pos, goal).item()
    )
    assert chamfer_distance(goal, goal).item() == 0.0
    batch = torch.stack([pos, pos + 1.0, pos - 2.0])  # [3, K, 2], one goal [M, 2] for all
    distances = chamfer_distance(batch, goal)
    assert distances.shape == (3,)
    for i in range(3):
        assert distances[i].item() == pytest.approx(chamfer_distance(batch[i], goal).item())


def test_unknown_objective_name_lists_the_names() -> None:
    with pytest.raises(ValueError, match="Unknown planning objective 'nope'") as info:
        goal_objective("nope")
    for name in OBJECTIVES:
        assert repr(name) in str(info.value)
    with pytest.raises(ValueError, match="Unknown planning objective"):
        goal_reward_head("nope")


def test_an_objective_is_returned_as_it_is() -> None:
    custom = GoalObjective("custom", "a test objective", KP_POS, GOAL_KP_POS, lambda s, g: s.sum())
    assert goal_objective(custom) is custom
    assert goal_objective(OBJECTIVES["keypoints"]) is OBJECTIVES["keypoints"]


@pytest.mark.parametrize("name", sorted(HAND))
@pytest.mark.parametrize("batch", [(), (4,), (2, 3)])
def test_goal_reward_head_writes_the_score_as_next_reward(name: str, batch: tuple) -> None:
    state_key, goal_key, state, goal, expected = HAND[name]
    head = goal_reward_head(name)
    next_key = ("next", *state_key) if isinstance(state_key, tuple) else ("next", state_key)
    assert list(head.in_keys) == [next_key, goal_key]
    assert list(head.out_keys) == [REWARD]
    td = TensorDict(
        {next_key: state.expand(*batch, *state.shape), goal_key: goal.expand(*batch, *goal.shape)},
        batch,
    )
    out = head(td)
    assert out is td
    reward = out.get(REWARD)
    assert reward.shape == (*batch, 1)
    torch.testing.assert_close(reward, torch.full((*batch, 1), expected))


def test_goal_reward_head_of_a_custom_objective() -> None:
    custom = GoalObjective(
        "sum", "sum of the state", OBJECT_POS, GOAL_OBJECT_POS, lambda s, g: (s - g).sum((-2, -1))
    )
    td = TensorDict(
        {("next", OBJECT_POS): torch.ones(3, 2, 2), GOAL_OBJECT_POS: torch.zeros(3, 2, 2)}, [3]
    )
    assert goal_reward_head(custom)(td).get(REWARD).tolist() == [[4.0]] * 3
