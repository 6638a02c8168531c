"""The methods of the rearrangement evaluation: one declaration each, with label and controller.

A method's controller factory gets a :class:`MethodContext` (the model, the episodes' scene, the
settings and the episode seeds: one controller plans for a batch of episodes). ``needs`` says
which model a method plans with: ``"kinet"`` (a :class:`~kinet_rl.models.KINetWorldModel`), ``"baseline"`` (IN, IN-full, VisIN, Forw, ForwInv or V-CDN) or
``None`` (random pushes and the oracle need no model).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Literal, cast

from torch import nn

from kinet_rl.envs.settings import SceneSettings
from kinet_rl.envs.workspace import workspace_for
from kinet_rl.keys import OBJECT_POS, OBJECT_SHAPE, OBJECT_YAW, PIXELS
from kinet_rl.models.model_env import (
    GraphDistanceReward,
    GraphSimilarityReward,
    KeypointChamferReward,
    KeypointDistanceReward,
    KeypointL2Reward,
    KINetReward,
)
from kinet_rl.models.push_planner import PushPlanner
from kinet_rl.models.world_model import KINetWorldModel
from kinet_rl.rearrangement.controllers import (
    BaselineMPCController,
    KINetController,
    OracleController,
    RandomController,
)
from kinet_rl.rearrangement.episodes import Controller
from kinet_rl.rearrangement.settings import Condition, RearrangementSettings

ModelKind = Literal["kinet", "baseline"] | None
#: What a camera gives: the observation of every controller that plans from images.
IMAGES = (PIXELS,)


@dataclass(frozen=True)
class MethodContext:
    """What a controller factory is given for a batch of episodes of one scene."""

    model: nn.Module | None
    scene: SceneSettings
    settings: RearrangementSettings
    seeds: tuple[int, ...]


@dataclass(frozen=True)
class Method:
    """A rearrangement method.

    Attributes:
        name: Its key in settings, summaries and JSON.
        label: How reports and tables name it.
        needs: The model it plans with (see the module docstring).
        make_controller: Builds its controller for a batch of episodes.
        observes: The observation entries its controller is handed each step: learned-model
            controllers see only what a real robot's camera gives (``pixels``); the GT-state
            baselines also get ``object_pos``, ``object_yaw`` and ``object_shape``, the oracle
            ``object_pos``.
    """

    name: str
    label: str
    needs: ModelKind
    make_controller: Callable[[MethodContext], Controller]
    observes: tuple[str, ...]

    def check_model(self, model: nn.Module | None) -> None:
        """Raises ``ValueError``/``TypeError`` naming the problem if this method cannot use ``model``."""
        if self.needs is not None and model is None:
            raise ValueError(f"Methods {[self.name]} need a model; pass model= or drop them.")
        if self.needs == "kinet" and not isinstance(model, KINetWorldModel):
            raise TypeError(
                f"Method {self.name!r} plans with KINet, got a {type(model).__name__}; use method "
                "'model_mpc' for baseline models."
            )
        if self.needs == "baseline" and isinstance(model, KINetWorldModel):
            raise TypeError(
                f"Method {self.name!r} plans with a baseline model (IN, VisIN, Forw, ForwInv or "
                "V-CDN), got KINet; use a kinet_* method."
            )

    def controller(self, ctx: MethodContext) -> Controller:
        """The method's controller for the context's episodes, after checking the model."""
        self.check_model(ctx.model)
        return self.make_controller(ctx)


def _kinet(reward: Callable[[], KINetReward]) -> Callable[[MethodContext], Controller]:
    def make(ctx: MethodContext) -> Controller:
        half_size = workspace_for(ctx.scene.task).half_size
        model = cast(KINetWorldModel, ctx.model)  # Method.controller checked it
        planner = PushPlanner(
            model, half_size, reward=reward(), seed=ctx.seeds, **dict(ctx.settings.planner)
        )
        return KINetController(planner)

    return make


def _oracle(ctx: MethodContext) -> Controller:
    settings = ctx.settings
    return OracleController(ctx.scene, settings.planner, settings.oracle_contact_radius, ctx.seeds)


METHODS: dict[str, Method] = {
    method.name: method
    for method in (
        Method(
            "kinet_graph",
            "KINet-GraphMPC (paper S, cosine)",
            "kinet",
            _kinet(GraphSimilarityReward),
            IMAGES,
        ),
        Method(
            "kinet_graph_dot",
            "KINet-GraphMPC (paper S, dot product)",
            "kinet",
            _kinet(lambda: GraphSimilarityReward("dot")),
            IMAGES,
        ),
        Method(
            "kinet_graph_distance",
            "KINet-GraphMPC (embedding distance)",
            "kinet",
            _kinet(GraphDistanceReward),
            IMAGES,
        ),
        Method(
            "kinet_keypoints",
            "MPC on keypoint positions",
            "kinet",
            _kinet(KeypointChamferReward),
            IMAGES,
        ),
        Method(
            "kinet_keypoints_l2",
            "MPC on index-matched keypoint positions (L2)",
            "kinet",
            _kinet(KeypointL2Reward),
            IMAGES,
        ),
        Method(
            "kinet_keypoints_distance",
            "MPC on index-matched keypoint distances (not squared)",
            "kinet",
            _kinet(KeypointDistanceReward),
            IMAGES,
        ),
        Method("random", "Random pushes", None, lambda ctx: RandomController(ctx.seeds), ()),
        Method(
            "oracle", "Oracle MPC (GT state, analytic push model)", None, _oracle, (OBJECT_POS,)
        ),
        Method(
            "model_mpc",
            "Baseline model MPC (distance to goal)",
            "baseline",
            lambda ctx: BaselineMPCController(
                cast(nn.Module, ctx.model), ctx.settings.planner, ctx.seeds
            ),
            # IN/IN-full/VisIN plan on GT state (Forw/ForwInv/V-CDN: pixels only)
            (PIXELS, OBJECT_POS, OBJECT_YAW, OBJECT_SHAPE),
        ),
    )
}


def check_methods(settings: RearrangementSettings) -> None:
    """Raises ``ValueError`` before any episode runs if ``settings`` name unknown methods."""
    unknown = [m for m in settings.methods if m not in METHODS]
    if unknown:
        raise ValueError(f"Unknown methods {unknown}; choose from {list(METHODS)}.")
    model_methods = [m.name for m in METHODS.values() if m.needs is not None]
    if settings.kinet_method not in model_methods:
        raise ValueError(
            f"kinet_method={settings.kinet_method!r}; choose one of {model_methods} (a KINet "
            "method, or model_mpc for a baseline such as V-CDN)."
        )


def check_model(conditions: Iterable[Condition], model: nn.Module | None) -> None:
    """Raises before any episode runs if a method of ``conditions`` cannot plan with ``model``."""
    for name in sorted({name for condition in conditions for name in condition.methods}):
        METHODS[name].check_model(model)
