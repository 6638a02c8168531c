"""Tests for the method registry and its checks of settings and models (no simulation)."""

from __future__ import annotations

import pytest

from kinet_rl.envs import SceneSettings
from kinet_rl.rearrangement.methods import METHODS, MethodContext, check_methods, check_model
from kinet_rl.rearrangement.settings import DEFAULT_METHODS, Condition, RearrangementSettings


def test_every_method_is_declared_once_with_a_label() -> None:
    assert set(DEFAULT_METHODS) < set(METHODS) and "model_mpc" in METHODS
    assert all(name == method.name and method.label for name, method in METHODS.items())
    kinet = [m.name for m in METHODS.values() if m.objective is not None]
    assert kinet == [
        "kinet_graph", "kinet_graph_dot", "kinet_graph_distance", "kinet_keypoints",
        "kinet_keypoints_l2", "kinet_keypoints_distance",
    ]  # fmt: skip
    assert all(METHODS[name].objective == name.removeprefix("kinet_") for name in kinet)
    assert {m.name for m in METHODS.values() if not m.plans_with_model} == {"random", "oracle"}


def test_bad_methods_are_reported() -> None:
    check_methods(RearrangementSettings())
    with pytest.raises(ValueError, match="Unknown methods"):
        check_methods(RearrangementSettings(methods=("kinet_graph", "teleport")))
    with pytest.raises(ValueError, match="kinet_method"):
        check_methods(RearrangementSettings(kinet_method="oracle"))


def test_a_baseline_of_any_object_count_plans_the_generalization_cells(tiny_baseline) -> None:
    settings = RearrangementSettings(
        methods=("model_mpc",),
        kinet_method="model_mpc",
        num_objects=(1, 5),
        backgrounds=("random",),
    )
    check_methods(settings)
    conditions = settings.conditions()
    assert {c.role for c in conditions} == {"comparison", "generalization", "background"}
    assert all("model_mpc" in c.methods for c in conditions)
    check_model(conditions, tiny_baseline("vcdn"))


def test_models_that_cannot_plan_a_method_are_reported(tiny_kinet, tiny_baseline) -> None:
    conditions = RearrangementSettings(methods=("random", "oracle")).conditions()
    check_model(conditions, None)  # no method needs a model
    with pytest.raises(ValueError, match=r"Methods \['kinet_graph'\] need a model"):
        check_model(RearrangementSettings(methods=("kinet_graph",)).conditions(), None)
    check_model(RearrangementSettings(methods=("model_mpc",)).conditions(), tiny_kinet())
    with pytest.raises(ValueError, match="'graph', which a VCDNWorldModel does not declare"):
        check_model(
            RearrangementSettings(methods=("kinet_graph",)).conditions(), tiny_baseline("vcdn")
        )


def test_a_policy_is_refused_for_the_wrong_model(tiny_kinet, tiny_baseline) -> None:
    settings = RearrangementSettings()
    context = MethodContext(tiny_baseline("in"), SceneSettings(), settings, seeds=(0,))
    with pytest.raises(ValueError, match="model_mpc"):
        METHODS["kinet_graph_distance"].policy(context)
    with pytest.raises(ValueError, match="need a model"):
        METHODS["kinet_graph"].policy(MethodContext(None, SceneSettings(), settings, (0,)))
    assert METHODS["random"].policy(MethodContext(None, SceneSettings(), settings, (0,)))
    check_model(RearrangementSettings(methods=("model_mpc",)).conditions(), tiny_baseline("in"))


def test_conditions_compare_by_value_so_worker_results_find_theirs() -> None:
    def condition(role: str) -> Condition:
        return Condition(SceneSettings(num_objects=2), role, ("random",), 3)

    assert condition("comparison") == condition("comparison")
    assert len({condition("comparison"), condition("comparison")}) == 1
    assert condition("generalization") != condition("comparison")


def test_a_policy_reads_only_what_its_model_declares(tiny_kinet, tiny_baseline) -> None:
    settings = RearrangementSettings(planner={"num_candidates": 8, "top_k": 2, "optim_steps": 1})

    def in_keys(method: str, model) -> list:
        scene = SceneSettings(image_size=16)
        return METHODS[method].policy(MethodContext(model, scene, settings, (0,))).in_keys

    for method in METHODS.values():
        if method.objective is not None:
            assert in_keys(method.name, tiny_kinet()) == ["pixels", ("goal", "pixels")]
    for name in ("forw", "forwinv", "vcdn"):
        assert in_keys("model_mpc", tiny_baseline(name)) == ["pixels", ("goal", "pixels")]
    goal = ("goal", "object_pos")
    assert in_keys("model_mpc", tiny_baseline("in")) == ["object_pos", goal]
    in_full = in_keys("model_mpc", tiny_baseline("in_full"))
    assert in_full == ["object_pos", "object_yaw", "object_shape", goal]  # GT-state ceilings
    assert in_keys("model_mpc", tiny_baseline("visin")) == ["pixels", "object_pos", goal]
    assert in_keys("oracle", None) == ["object_pos", goal]
    assert in_keys("random", None) == []
