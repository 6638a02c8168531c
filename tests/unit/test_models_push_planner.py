"""Tests for PushPlanner, the goal-conditioned planning API for a robot."""

from __future__ import annotations

import pytest
import torch

from kinet_rl.models import GraphDistanceReward, Push, PushPlanner

PLANNER = dict(planning_horizon=2, optim_steps=2, num_candidates=16, top_k=4)


def test_next_push_is_in_metres_and_normalised_units(tiny_kinet, random_images) -> None:
    planner = PushPlanner(tiny_kinet(), workspace_half_size=0.2, seed=0, **PLANNER)
    assert isinstance(planner.env.reward, GraphDistanceReward)  # the default objective
    push = planner.next_push(random_images((), 0).numpy(), random_images((), 1).numpy())
    assert isinstance(push, Push)
    assert all(-1.0 <= v <= 1.0 for v in push.normalised)
    assert push.start_xy_m == pytest.approx((0.2 * push.normalised[0], 0.2 * push.normalised[1]))
    assert push.end_xy_m == pytest.approx((0.2 * push.normalised[2], 0.2 * push.normalised[3]))
    assert planner.last_keypoints.shape == (4, 2)
    assert set(push.as_dict()) == {"start_xy_m", "end_xy_m", "normalised"}


def test_same_seed_same_push(tiny_kinet, random_images) -> None:
    pushes = [
        PushPlanner(tiny_kinet(), 0.2, seed=3, **PLANNER).next_push(
            random_images((), 0), random_images((), 1)
        )
        for _ in range(2)
    ]
    assert pushes[0] == pushes[1]


def test_warm_start_kept_between_calls_and_cleared_on_new_goal(tiny_kinet, random_images) -> None:
    planner = PushPlanner(tiny_kinet(), 0.2, seed=0, **PLANNER)
    goal = random_images((), 1)
    planner.next_push(random_images((), 0), goal)
    first_plan = planner.planner.plan.clone()
    seen = []
    inner = planner.planner._initial_mean
    planner.planner._initial_mean = lambda td: seen.append(inner(td)) or seen[-1]
    planner.next_push(random_images((), 2), goal)
    assert torch.allclose(seen[-1][0, 0], first_plan[1])  # shifted previous plan
    planner.next_push(
        random_images((), 2), random_images((), 5)
    )  # new goal: cold start at the centre
    assert torch.equal(seen[-1], torch.zeros_like(seen[-1]))


def test_bad_images_are_reported(tiny_kinet, random_images) -> None:
    planner = PushPlanner(tiny_kinet(), 0.2, **PLANNER)
    with pytest.raises(ValueError, match="RGB"):
        planner.next_push(torch.zeros(16, 16, 4, dtype=torch.uint8), random_images((), 1))
    with pytest.raises(TypeError, match="uint8"):
        planner.next_push(torch.zeros(16, 16, 3), random_images((), 1))
    with pytest.raises(ValueError, match="workspace_half_size"):
        PushPlanner(tiny_kinet(), 0.0)


def test_next_pushes_plans_each_scene_as_its_own_seeded_planner(tiny_kinet, random_images) -> None:
    model = tiny_kinet()
    images, goals = random_images((3,), 0), random_images((3,), 1)
    together = PushPlanner(model, 0.2, seed=(4, 5, 6), **PLANNER).next_pushes(images, goals)
    for i, seed in enumerate((4, 5, 6)):
        alone = PushPlanner(model, 0.2, seed=(seed,), **PLANNER)
        (push,) = alone.next_pushes(images[i : i + 1], goals[i : i + 1])
        assert push.normalised == pytest.approx(together[i].normalised, abs=1e-5)
    assert len({push.normalised for push in together}) == 3  # different scenes, different pushes
    with pytest.raises(ValueError, match="next_push for one image"):
        PushPlanner(model, 0.2, **PLANNER).next_pushes(images[0], goals[0])
