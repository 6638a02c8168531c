"""Tests for the method registry and its checks of settings and models (no simulation)."""

from __future__ import annotations

import pytest

from kinet_rl.envs import SceneSettings
from kinet_rl.rearrangement.methods import METHODS, MethodContext, check_methods, check_model
from kinet_rl.rearrangement.settings import DEFAULT_METHODS, Condition, RearrangementSettings


def test_every_method_is_declared_once_with_a_label() -> None:
    assert set(DEFAULT_METHODS) < set(METHODS) and "model_mpc" in METHODS
    assert all(name == method.name and method.label for name, method in METHODS.items())
    kinet = [m.name for m in METHODS.values() if m.needs == "kinet"]
    assert kinet == [
        "kinet_graph", "kinet_graph_dot", "kinet_graph_distance", "kinet_keypoints",
        "kinet_keypoints_l2", "kinet_keypoints_distance",
    ]  # fmt: skip
    assert {m.name for m in METHODS.values() if m.needs is None} == {"random", "oracle"}


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


def test_models_that_cannot_plan_a_method_are_reported(tiny_kinet) -> None:
    conditions = RearrangementSettings(methods=("random", "oracle")).conditions()
    check_model(conditions, None)  # no method needs a model
    with pytest.raises(ValueError, match=r"Methods \['kinet_graph'\] need a model"):
        check_model(RearrangementSettings(methods=("kinet_graph",)).conditions(), None)
    with pytest.raises(TypeError, match="kinet_"):
        check_model(RearrangementSettings(methods=("model_mpc",)).conditions(), tiny_kinet())


def test_a_controller_is_refused_for_the_wrong_model(tiny_kinet, tiny_baseline) -> None:
    settings = RearrangementSettings()
    context = MethodContext(tiny_baseline("in"), SceneSettings(), settings, seeds=(0,))
    with pytest.raises(TypeError, match="plans with KINet"):
        METHODS["kinet_graph_distance"].controller(context)
    with pytest.raises(ValueError, match="need a model"):
        METHODS["kinet_graph"].controller(MethodContext(None, SceneSettings(), settings, (0,)))
    assert METHODS["random"].controller(MethodContext(None, SceneSettings(), settings, (0,)))
    check_model(RearrangementSettings(methods=("model_mpc",)).conditions(), tiny_baseline("in"))


def test_conditions_compare_by_value_so_worker_results_find_theirs() -> None:
    def condition(role: str) -> Condition:
        return Condition(SceneSettings(num_objects=2), role, ("random",), 3)

    assert condition("comparison") == condition("comparison")
    assert len({condition("comparison"), condition("comparison")}) == 1
    assert condition("generalization") != condition("comparison")


def test_methods_that_plan_from_images_observe_only_images() -> None:
    for method in METHODS.values():
        if method.needs == "kinet":
            assert method.observes == ("pixels",), method.name
    assert "object_pos" in METHODS["model_mpc"].observes  # IN/VisIN: GT-state ceilings
