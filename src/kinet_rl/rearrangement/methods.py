"""The methods of the rearrangement evaluation: one declaration each, with label and policy.

A method's policy factory gets a :class:`MethodContext` (the model, the episodes' scene, the
settings and the episode seeds: one policy plans for a batch of episodes). A planning method
plans with the model through a :class:`~kinet_rl.models.PushPlanner` and a planning objective:
``kinet_<objective>`` with that objective of :data:`~kinet_rl.planners.OBJECTIVES` (any model
that declares it: KINet's graph and keypoint objectives), ``model_mpc`` with the model's own
(a baseline's distance to the goal). Random pushes and the oracle need no model.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

from kinet_rl.baselines.oracle import AnalyticPushModel
from kinet_rl.envs.settings import SceneSettings
from kinet_rl.envs.workspace import workspace_for
from kinet_rl.models.push_planner import PushPlanner
from kinet_rl.planners.world_model import ModelCapabilities, PlanningDefaults, PlanningInterface
from kinet_rl.rearrangement.episodes import Policy
from kinet_rl.rearrangement.policies import PlannerPolicy, RandomPolicy
from kinet_rl.rearrangement.settings import Condition, RearrangementSettings


@dataclass(frozen=True)
class MethodContext:
    """What a policy factory is given for a batch of episodes of one scene."""

    model: PlanningInterface | None
    scene: SceneSettings
    settings: RearrangementSettings
    seeds: tuple[int, ...]


@dataclass(frozen=True)
class Method:
    """A rearrangement method.

    Attributes:
        name: Its key in settings, summaries and JSON.
        label: How reports and tables name it.
        plans_with_model: Whether it plans with the evaluated model.
        objective: The planning objective of a model method (None: the model's own).
        make_policy: Builds its policy for a batch of episodes; the policy declares what it
            reads (``in_keys``: what its model declares; random pushes read nothing, the oracle
            object positions and goal positions).
    """

    name: str
    label: str
    plans_with_model: bool
    objective: str | None
    make_policy: Callable[[MethodContext], Policy]

    def plans_with(self, capabilities: ModelCapabilities) -> bool:
        """Whether this method can plan with a model that declares ``capabilities``."""
        return self.objective is None or self.objective in capabilities.objectives

    def check_model(self, model: PlanningInterface | None) -> None:
        """Raises ``ValueError`` naming the problem if this method cannot use ``model``."""
        if not self.plans_with_model:
            return
        if model is None:
            raise ValueError(f"Methods {[self.name]} need a model; pass model= or drop them.")
        objectives = model.capabilities.objectives
        if not self.plans_with(model.capabilities):
            raise ValueError(
                f"Method {self.name!r} plans with the objective {self.objective!r}, which a "
                f"{type(model).__name__} does not declare (it plans with {list(objectives)}); use "
                "method 'model_mpc' for a model's own objective."
            )

    def policy(self, ctx: MethodContext) -> Policy:
        """The method's policy for the context's episodes, after checking the model."""
        self.check_model(ctx.model)
        return self.make_policy(ctx)


def _planning(objective: str | None) -> Callable[[MethodContext], Policy]:
    def make(ctx: MethodContext) -> Policy:
        assert ctx.model is not None  # Method.policy checked it
        return _planner_policy(ctx.model, objective, ctx)

    return make


def _planner_policy(model: PlanningInterface, objective: str | None, ctx: MethodContext) -> Policy:
    half_size = workspace_for(ctx.scene.task).half_size
    planner = PushPlanner(
        model, objective, dict(ctx.settings.planner), workspace_half_size=half_size, seed=ctx.seeds
    )
    return PlannerPolicy(planner)


def _oracle(ctx: MethodContext) -> Policy:
    half_size = workspace_for(ctx.scene.task).half_size
    oracle = AnalyticPushModel(ctx.scene.num_objects, half_size, ctx.settings.oracle_contact_radius)
    return _planner_policy(oracle, None, ctx)


def _kinet(objective: str, label: str) -> Method:
    return Method(f"kinet_{objective}", label, True, objective, _planning(objective))


METHODS: dict[str, Method] = {
    method.name: method
    for method in (
        _kinet("graph", "KINet-GraphMPC (paper S, cosine)"),
        _kinet("graph_dot", "KINet-GraphMPC (paper S, dot product)"),
        _kinet("graph_distance", "KINet-GraphMPC (embedding distance)"),
        _kinet("keypoints", "MPC on keypoint positions"),
        _kinet("keypoints_l2", "MPC on index-matched keypoint positions (L2)"),
        _kinet("keypoints_distance", "MPC on index-matched keypoint distances (not squared)"),
        Method("random", "Random pushes", False, None, lambda ctx: RandomPolicy(ctx.seeds)),
        Method(
            "oracle",
            "Oracle MPC (GT state, analytic push model)",
            False,
            None,
            _oracle,
        ),
        Method(
            "model_mpc",
            "Baseline model MPC (distance to goal)",
            True,
            None,
            _planning(None),
        ),
    )
}


def plans_every_method(capabilities: ModelCapabilities, settings: RearrangementSettings) -> bool:
    """Whether a model that declares ``capabilities`` can plan every method of ``settings``."""
    return all(METHODS[name].plans_with(capabilities) for name in settings.methods)


def validated_planning(
    model: PlanningInterface, settings: RearrangementSettings
) -> PlanningDefaults:
    """The planning defaults an experiment stores with its model: the objective of its
    ``kinet_method`` (chosen on validation episodes) where the model declares it, else the
    model's own, with the evaluation's planner settings."""
    objective = METHODS[settings.kinet_method].objective
    if objective is None or objective not in model.capabilities.objectives:
        objective = model.planning.objective
    return PlanningDefaults(objective, dict(settings.planner))


def check_methods(settings: RearrangementSettings) -> None:
    """Raises ``ValueError`` before any episode runs if ``settings`` name unknown methods."""
    unknown = [m for m in settings.methods if m not in METHODS]
    if unknown:
        raise ValueError(f"Unknown methods {unknown}; choose from {list(METHODS)}.")
    model_methods = [m.name for m in METHODS.values() if m.plans_with_model]
    if settings.kinet_method not in model_methods:
        raise ValueError(
            f"kinet_method={settings.kinet_method!r}; choose one of {model_methods} (a KINet "
            "method, or model_mpc for a baseline such as V-CDN)."
        )


def check_model(conditions: Iterable[Condition], model: PlanningInterface | None) -> None:
    """Raises before any episode runs if a method of ``conditions`` cannot plan with ``model``."""
    for name in sorted({name for condition in conditions for name in condition.methods}):
        METHODS[name].check_model(model)
