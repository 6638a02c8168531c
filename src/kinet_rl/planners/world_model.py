"""The world-model interface every pushing model implements, and its TorchRL ``WorldModelEnv``.

A model that plans (KINet and its variants, the baselines, the oracle's analytic push model)
implements :class:`PlanningInterface`: it declares what it observes and can do
(:class:`ModelCapabilities`) and builds a :class:`PushWorldModel` (a
``torchrl.modules.WorldModel``: encoder, one-push dynamics, goal reward head, optional decoder)
for a planning objective of :data:`~kinet_rl.planners.objectives.OBJECTIVES`.
:class:`PushWorldModelEnv` is its ``torchrl.envs.model_based.WorldModelEnv``, over which
``GraphMPCPlanner`` and torchrl's ``CEMPlanner`` and ``MPPIPlanner`` plan alike.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol, runtime_checkable

import torch
from tensordict import NestedKey, TensorDictBase
from tensordict.nn import TensorDictModule, TensorDictModuleBase
from torch import Tensor, nn
from torchrl.data import Bounded, Composite, Unbounded
from torchrl.envs.model_based import ModelBasedEnvBase, WorldModelEnv
from torchrl.modules import WorldModel

from kinet_rl.keys import GOAL_PIXELS, PIXELS
from kinet_rl.planners.objectives import goal_objective

#: Dimension of the push action (start x, start y, end x, end y), each in ``[-1, 1]``.
ACTION_DIM = 4


#: The planner budget the published results use (64 candidates x 3 iterations, one-step horizon,
#: acting on the best sequence scored), chosen on validation episodes: docs/results.md; the same
#: as conf/eval/rearrange.yaml's ``planner``.
VALIDATED_PLANNER: dict[str, Any] = {
    "planning_horizon": 1,
    "optim_steps": 3,
    "num_candidates": 64,
    "top_k": 8,
    "update_rule": "cem",
    "temperature": 0.5,
    "min_std": 0.05,
    "max_std": 1.0,
    "return_best": True,
}


@dataclass(frozen=True)
class ModelCapabilities:
    """What a model needs and can do, declared by the model.

    Attributes:
        observes: Observation entries its encoder reads (``pixels`` for a camera; ground-truth
            object state for IN, IN-full, VisIN and the oracle).
        goal: Goal entries its encoder reads (the goal image, or goal object positions).
        objectives: Planning objectives it can plan with (names of ``OBJECTIVES``).
        any_object_count: Trains and plans on scenes with any number of objects.
        reconstructs: Has a decoder (image reconstruction).
        keypoints: Detects keypoints (keypoint accuracy, detector floor, overlays).
    """

    observes: tuple[str, ...]
    goal: tuple[NestedKey, ...]
    objectives: tuple[str, ...]
    any_object_count: bool = False
    reconstructs: bool = False
    keypoints: bool = False

    @property
    def needs_ground_truth(self) -> bool:
        """Whether it reads simulator state that a real robot's camera does not give."""
        return any(key != PIXELS for key in self.observes)

    @property
    def plans_from_images(self) -> bool:
        """Whether current and goal are camera images (``plan --image --goal`` works)."""
        return self.observes == (PIXELS,) and self.goal == (GOAL_PIXELS,)


@dataclass(frozen=True)
class PlanningDefaults:
    """The planning objective and planner settings a model plans with unless told otherwise.

    Chosen on validation episodes and stored in the model's checkpoint, so that planning with a
    loaded model reproduces how its results were produced.

    Attributes:
        objective: Name in ``OBJECTIVES``.
        planner: ``GraphMPCPlanner`` settings (budget, update rule, ``return_best``...).
    """

    objective: str
    planner: Mapping[str, Any] = field(default_factory=lambda: dict(VALIDATED_PLANNER))

    def __post_init__(self) -> None:
        goal_objective(self.objective)

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly form (checkpoints, model cards)."""
        return {"objective": self.objective, "planner": dict(self.planner)}

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> PlanningDefaults:
        """The defaults :meth:`as_dict` wrote."""
        return cls(str(values["objective"]), dict(values.get("planner", {})))


class _NeverDone(nn.Module):
    """A push never ends an imagined episode: ``done`` and ``terminated`` ``[*B, 1]`` are False."""

    def __init__(self, event_dims: int) -> None:
        super().__init__()
        self.event_dims = event_dims

    def forward(self, state: Tensor) -> tuple[Tensor, Tensor]:
        batch = state.shape[: state.dim() - self.event_dims]
        done = torch.zeros(*batch, 1, dtype=torch.bool, device=state.device)
        return done, done


class PushWorldModel(WorldModel):
    """A ``torchrl.modules.WorldModel`` of pushes, with the shapes of the state it carries.

    Args:
        encoder: Observation and goal (``[*B]``) -> the start state, goal entries included.
        dynamics: One push: the state and ``action`` -> ``("next", ...)`` state and goal.
        reward_head: ``goal_reward_head(objective)``.
        state_shapes: Per-element shape of every state entry the dynamics carries (goal too).
        decoder: Optional reconstruction.
    """

    def __init__(
        self,
        encoder: TensorDictModuleBase,
        dynamics: TensorDictModuleBase,
        reward_head: TensorDictModuleBase,
        state_shapes: Mapping[NestedKey, tuple[int, ...]],
        decoder: TensorDictModuleBase | None = None,
    ) -> None:
        latent = next(iter(state_shapes))
        never_done = TensorDictModule(
            _NeverDone(len(state_shapes[latent])),
            in_keys=[("next", *latent) if isinstance(latent, tuple) else ("next", latent)],
            out_keys=[("next", "done"), ("next", "terminated")],
        )
        super().__init__(
            encoder,
            dynamics,
            reward_head,
            done_head=never_done,
            decoder=decoder,  # type: ignore[arg-type]
        )
        self.state_shapes = dict(state_shapes)

    @property
    def latent_key(self) -> NestedKey:
        """The state entry ``WorldModelEnv.reset`` checks for."""
        return next(iter(self.state_shapes))

    @torch.no_grad()
    def observe(self, observation: TensorDictBase) -> TensorDictBase:
        """The start state of ``observation`` (its batch): the encoder's output, state keys only.

        Raises:
            KeyError: ``observation`` lacks an entry the encoder reads (named).
        """
        given = set(observation.keys(True, True))
        missing = [key for key in self.encoder.in_keys if key not in given]
        if missing:
            raise KeyError(
                f"The observation lacks {missing}; this world model encodes "
                f"{list(self.encoder.in_keys)} (the model's capabilities.observes and .goal)."
            )
        return self.encode(observation.copy()).select(*self.state_shapes)


@runtime_checkable
class PlanningInterface(Protocol):
    """What every model that plans implements."""

    capabilities: ClassVar[ModelCapabilities]
    planning: PlanningDefaults
    #: The scene it was trained on (image size, workspace), when known: ``SceneSettings``.
    scene: Any

    def world_model(self, objective: str | None = None) -> PushWorldModel:
        """Its world model planning with ``objective`` (default ``planning.objective``)."""
        ...


def check_objective(capabilities: ModelCapabilities, name: str, model: str) -> str:
    """``name``, after checking that a model with ``capabilities`` can plan with it."""
    goal_objective(name)
    if name not in capabilities.objectives:
        raise ValueError(
            f"{model} cannot plan with the objective {name!r}; it plans with "
            f"{list(capabilities.objectives)}."
        )
    return name


class CarryStep(nn.Module):
    """A one-push step as a plain function of tensors, with the goal entries carried along."""

    def __init__(self, step: nn.Module, goals: int) -> None:
        super().__init__()
        self.step = step
        self.goals = goals

    def forward(self, *tensors: Tensor) -> tuple[Tensor, ...]:
        goals = tensors[len(tensors) - self.goals :]
        return (*self.step(*tensors[: len(tensors) - self.goals]), *goals)


def push_dynamics(
    step: nn.Module,
    in_keys: list[NestedKey],
    out_keys: list[NestedKey],
    goal_keys: list[NestedKey],
) -> TensorDictModule:
    """The dynamics module of a push model: ``step(*in_keys) -> out_keys`` under ``"next"``,
    with ``goal_keys`` copied to ``"next"`` so the goal travels along imagined rollouts."""

    def nxt(key: NestedKey) -> NestedKey:
        return ("next", *key) if isinstance(key, tuple) else ("next", key)

    return TensorDictModule(
        CarryStep(step, len(goal_keys)),
        in_keys=[*in_keys, *goal_keys],
        out_keys=[nxt(key) for key in (*out_keys, *goal_keys)],
    )


class PushWorldModelEnv(WorldModelEnv):
    """torchrl's ``WorldModelEnv`` for imagined pushes, batch-less (not batch-locked).

    Planners roll out ``[*B, candidates]`` tensordicts through a batch-less env. torchrl 0.14's
    ``WorldModelEnv`` cannot be one: it builds its specs by expanding a reference env's to its
    batch size (which fails for a 4-d action) and writes its step output and reset flags at that
    batch size. This subclass sets the specs directly and keeps ``WorldModelEnv``'s contract at
    the tensordict's batch: a step runs the world model's dynamics and heads, not the encoder;
    reset takes the start state, ``world_model.observe(observation)``.

    Args:
        world_model: The model's :class:`PushWorldModel`.
        device: Device of the state (default: that of the model's parameters, else CPU).
    """

    def __init__(
        self, world_model: PushWorldModel, device: torch.device | str | None = None
    ) -> None:
        if device is None:
            device = next(world_model.parameters(), torch.empty(0)).device
        ModelBasedEnvBase.__init__(
            self,
            world_model.step_module,
            device=device,
            batch_size=torch.Size([]),
            allow_done_after_reset=True,
        )
        self._world_model = world_model
        self.latent_key = world_model.latent_key
        self.observation_spec = Composite(
            {
                key: Unbounded(shape, device=device)
                for key, shape in world_model.state_shapes.items()
            },
            device=device,
        )
        self.action_spec = Bounded(-1.0, 1.0, (ACTION_DIM,), device=device)
        self.reward_spec = Unbounded((1,), device=device)
        self._step_keys: list[NestedKey] | None = None

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        if self._step_keys is None:  # what a step returns, read from the specs once
            self._step_keys = [
                *self.observation_spec.keys(True, True),
                *self.full_reward_spec.keys(True, True),
                *self.full_done_spec.keys(True, True),
            ]
        return self.world_model(tensordict.copy()).get("next").select(*self._step_keys)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        keys = list(self.observation_spec.keys(True, True))
        given = set() if tensordict is None else set(tensordict.keys(True, True))
        missing = [key for key in keys if key not in given]
        if missing:
            raise KeyError(
                f"Reset an imagined pushing env with its start state {keys} (missing: {missing}): "
                "world_model.observe(observation) builds it from an observation and a goal."
            )
        out = tensordict.copy()
        out.update(self.full_done_spec.zero(tensordict.batch_size))
        return out
