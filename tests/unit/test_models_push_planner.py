"""Tests for PushPlanner, the goal-conditioned planning API for a robot."""

from __future__ import annotations

import pytest
import torch

from kinet_rl.envs import SceneSettings
from kinet_rl.models import KINetWorldModel, Push, PushPlanner
from kinet_rl.planners import VALIDATED_PLANNER, PlanningDefaults

PLANNER = dict(planning_horizon=2, optim_steps=2, num_candidates=16, top_k=4)


def planner_of(model, seed=None, **kwargs) -> PushPlanner:
    return PushPlanner(model, planner=PLANNER, workspace_half_size=0.2, seed=seed, **kwargs)


def test_next_push_is_in_metres_and_normalised_units(tiny_kinet, random_images) -> None:
    planner = planner_of(tiny_kinet(), seed=0)
    assert planner.objective == "keypoints_l2"  # KINet's validated objective
    push = planner.next_push(random_images((), 0).numpy(), random_images((), 1).numpy())
    assert isinstance(push, Push)
    assert all(-1.0 <= v <= 1.0 for v in push.normalised)
    assert push.start_xy_m == pytest.approx((0.2 * push.normalised[0], 0.2 * push.normalised[1]))
    assert push.end_xy_m == pytest.approx((0.2 * push.normalised[2], 0.2 * push.normalised[3]))
    assert planner.last_keypoints.shape == (1, 4, 2)
    assert set(push.as_dict()) == {"start_xy_m", "end_xy_m", "normalised"}


def test_same_seed_same_push(tiny_kinet, random_images) -> None:
    pushes = [
        planner_of(tiny_kinet(), seed=3).next_push(random_images((), 0), random_images((), 1))
        for _ in range(2)
    ]
    assert pushes[0] == pushes[1]


def test_warm_start_kept_between_calls_and_cleared_on_new_goal(tiny_kinet, random_images) -> None:
    planner = planner_of(tiny_kinet(), seed=0)
    goal = random_images((), 1)
    planner.next_push(random_images((), 0), goal)
    first_plan = planner.planner.plan.clone()
    seen = []
    inner = planner.planner._initial_mean
    planner.planner._initial_mean = lambda td: seen.append(inner(td)) or seen[-1]
    planner.next_push(random_images((), 2), goal)
    assert torch.allclose(seen[-1][0, 0, 0], first_plan[0, 1])  # shifted previous plan
    planner.next_push(
        random_images((), 2), random_images((), 5)
    )  # new goal: cold start at the centre
    assert torch.equal(seen[-1], torch.zeros_like(seen[-1]))


def test_bad_images_are_reported(tiny_kinet, random_images) -> None:
    planner = planner_of(tiny_kinet())
    with pytest.raises(ValueError, match="RGB"):
        planner.next_push(torch.zeros(16, 16, 4, dtype=torch.uint8), random_images((), 1))
    with pytest.raises(TypeError, match="uint8"):
        planner.next_push(torch.zeros(16, 16, 3), random_images((), 1))
    with pytest.raises(ValueError, match="workspace_half_size"):
        PushPlanner(tiny_kinet(), workspace_half_size=0.0)
    with pytest.raises(ValueError, match="pass workspace_half_size"):
        PushPlanner(tiny_kinet())  # no scene known, no workspace given


def test_next_pushes_plans_each_scene_as_its_own_seeded_planner(tiny_kinet, random_images) -> None:
    model = tiny_kinet()
    images, goals = random_images((3,), 0), random_images((3,), 1)
    together = planner_of(model, seed=(4, 5, 6)).next_pushes(images, goals)
    for i, seed in enumerate((4, 5, 6)):
        alone = planner_of(model, seed=(seed,))
        (push,) = alone.next_pushes(images[i : i + 1], goals[i : i + 1])
        assert push.normalised == pytest.approx(together[i].normalised, abs=1e-5)
    assert len({push.normalised for push in together}) == 3  # different scenes, different pushes
    with pytest.raises(ValueError, match="next_push for one image"):
        planner_of(model).next_pushes(images[0], goals[0])


def test_the_planner_plans_with_the_objective_budget_and_scene_stored_in_the_checkpoint(
    tiny_kinet, tmp_path
) -> None:
    model = tiny_kinet()
    budget = {**VALIDATED_PLANNER, "num_candidates": 24, "top_k": 6, "optim_steps": 2}
    model.planning = PlanningDefaults("keypoints_distance", budget)
    model.save_checkpoint(tmp_path / "kinet.pt", SceneSettings(task="ycb", image_size=16))
    loaded = KINetWorldModel.from_checkpoint(tmp_path / "kinet.pt")
    assert loaded.planning == PlanningDefaults("keypoints_distance", budget)
    planner = PushPlanner(loaded)  # no other argument
    assert planner.objective == "keypoints_distance"
    assert planner.planner.num_candidates == 24 and planner.planner.top_k == 6
    assert planner.planner.optim_steps == 2 and planner.planner.return_best
    assert planner.workspace_half_size == pytest.approx(0.30)  # YCB's workspace
    assert planner.image_size == 16
    assert KINetWorldModel.planning == PlanningDefaults("keypoints_l2")  # class default untouched
    overridden = PushPlanner(loaded, objective="graph", planner=PLANNER)
    assert overridden.objective == "graph" and overridden.planner.num_candidates == 16


def test_images_of_another_size_than_the_model_or_each_other_are_refused(
    tiny_kinet, random_images, tmp_path
) -> None:
    tiny_kinet().save_checkpoint(tmp_path / "kinet.pt", SceneSettings(image_size=16))
    planner = PushPlanner(KINetWorldModel.from_checkpoint(tmp_path / "kinet.pt"), planner=PLANNER)
    with pytest.raises(ValueError, match=r"24x24 px but the model was trained on 16x16"):
        planner.next_push(random_images((), 0, size=24), random_images((), 1, size=24))
    with pytest.raises(ValueError, match=r"goal image is 24x24 px but the current image is 16x16"):
        planner.next_push(random_images((), 0), random_images((), 1, size=24))
    planner.next_push(random_images((), 0), random_images((), 1))


def test_an_objective_the_model_does_not_declare_is_refused(tiny_kinet, tiny_baseline) -> None:
    with pytest.raises(ValueError, match="cannot plan with the objective 'object_distance'"):
        planner_of(tiny_kinet(), objective="object_distance")
    with pytest.raises(ValueError, match="Unknown planning objective"):
        planner_of(tiny_kinet(), objective="teleport")
    with pytest.raises(TypeError, match="not from images alone"):
        planner_of(tiny_baseline("in")).next_push(
            torch.zeros(16, 16, 3, dtype=torch.uint8), torch.zeros(16, 16, 3, dtype=torch.uint8)
        )
