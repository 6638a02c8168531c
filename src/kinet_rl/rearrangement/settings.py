"""Settings of the rearrangement evaluation: the task, the planners, and the conditions to run.

Plain data only (no models, no envs), so that reports and callers can depend on it alone.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any, Literal

from kinet_rl.config_schema import at_least, check_keys, config_group, require, settings_from
from kinet_rl.envs.settings import BACKGROUNDS, GEOMETRIES, MAX_OBJECTS, SceneSettings
from kinet_rl.planners.graph_mpc import check_planner_settings

#: The comparison's methods by default (names of :data:`kinet_rl.rearrangement.methods.METHODS`).
DEFAULT_METHODS = (
    "kinet_graph",
    "kinet_graph_dot",
    "kinet_graph_distance",
    "kinet_keypoints",
    "kinet_keypoints_l2",
    "random",
    "oracle",
)

Role = Literal["comparison", "generalization", "background"]
Split = Literal["validation", "test"]

#: Seed of the first episode of each split: episode ``i`` uses ``SPLIT_SEEDS[split] + i``. Costs,
#: planner settings and defaults are chosen on validation episodes and reported on test episodes,
#: which are never looked at while choosing (up to 40,000 validation episodes stay disjoint).
#: Training data never uses these seeds: collection seeds episodes by a hash of (run seed, index).
SPLIT_SEEDS: dict[str, int] = {"validation": 10_000, "test": 50_000}


@dataclass(frozen=True)
class TaskSettings:
    """Rearrangement task and metric settings (see :mod:`kinet_rl.rearrangement.episodes`)."""

    num_steps: int = 40
    goal_pushes: int = 4
    min_goal_distance: float = 0.03
    success_threshold: float = 0.03
    max_goal_tries: int = 20

    def __post_init__(self) -> None:
        at_least(self, 1, "num_steps", "goal_pushes", "max_goal_tries")
        at_least(self, 0, "min_goal_distance")
        require(
            self.success_threshold > 0, "success_threshold", self.success_threshold, "metres > 0"
        )


def planner_budget(optim_steps: int, num_candidates: int, top_k: int) -> dict[str, Any]:
    """:class:`~kinet_rl.planners.GraphMPCPlanner` settings of a one-push-horizon budget that acts
    on the best sequence scored (``return_best``, chosen on validation episodes)."""
    return {
        "planning_horizon": 1,
        "optim_steps": optim_steps,
        "num_candidates": num_candidates,
        "top_k": top_k,
        "return_best": True,
    }


def generalization_key(num_objects: int, geometry: str) -> str:
    """The name of a Table II cell in summaries and JSON, e.g. ``"n3_geom_train"``."""
    return f"n{num_objects}_geom_{geometry}"


@dataclass(frozen=True)
class Condition:
    """A scene on which some methods are evaluated.

    Attributes:
        scene: The scene (its ``num_objects``, ``geometry`` and ``background`` vary by condition).
        role: ``"comparison"`` (the training scene, every method), ``"generalization"`` (a Table
            II cell) or ``"background"`` (another background).
        methods: Method names run on it.
        episodes: Episodes per method.
    """

    scene: SceneSettings
    role: Role
    methods: tuple[str, ...]
    episodes: int

    @property
    def name(self) -> str:
        """The condition's key in summaries and JSON files."""
        if self.role == "comparison":
            return "comparison"
        if self.role == "generalization":
            return generalization_key(self.scene.num_objects, self.scene.geometry)
        return f"background_{self.scene.background}"


@dataclass(frozen=True)
class RearrangementSettings:
    """Settings of the rearrangement evaluation (mirrors ``conf/eval/rearrange.yaml``).

    Attributes:
        scene: The training scene (comparisons run on it).
        task: Task and metric settings.
        episodes: Episodes per method in the comparison.
        methods: Methods of the comparison (names in ``kinet_rl.rearrangement.METHODS``).
        planner: :class:`GraphMPCPlanner` settings (the budget) of every planning method: the
            learned-model policies and the oracle plan with the same budget.
        oracle_contact_radius: Object-plus-pusher radius of the oracle's push model, metres.
        num_objects: Object counts of the generalization table (empty: skipped).
        geometries: Geometries of the generalization table.
        backgrounds: Extra backgrounds to test (e.g. ``["random"]``; empty: skipped).
        generalization_episodes: Episodes per generalization cell.
        workers: Parallel worker processes (<= 1 runs inline).
        batch_episodes: Episodes of one condition and method that a worker runs in lockstep,
            planned in one batched planner call per step (1: one episode at a time).
        split: ``"validation"`` (choosing) or ``"test"`` (reporting) episodes, see
            :data:`SPLIT_SEEDS`.
        videos: Episodes of ``kinet_method`` recorded as GIFs.
        kinet_method: The planner of the generalization conditions, backgrounds and videos: a
            KINet method, or ``model_mpc`` for a baseline that handles any object count (V-CDN).
    """

    scene: SceneSettings = field(default_factory=SceneSettings)
    task: TaskSettings = field(default_factory=TaskSettings)
    episodes: int = 4
    methods: tuple[str, ...] = DEFAULT_METHODS
    planner: Mapping[str, Any] = field(default_factory=lambda: planner_budget(3, 64, 8))
    oracle_contact_radius: float = 0.035
    num_objects: tuple[int, ...] = ()
    geometries: tuple[str, ...] = ("train", "gen")
    backgrounds: tuple[str, ...] = ()
    generalization_episodes: int = 2
    workers: int = 2
    batch_episodes: int = 1
    split: Split = "test"
    videos: int = 1
    kinet_method: str = "kinet_keypoints_l2"

    def __post_init__(self) -> None:
        at_least(self, 1, "episodes", "generalization_episodes", "batch_episodes")
        at_least(self, 0, "videos")
        require(self.split in SPLIT_SEEDS, "split", self.split, f"one of {list(SPLIT_SEEDS)}")
        require(
            self.oracle_contact_radius > 0,
            "oracle_contact_radius",
            self.oracle_contact_radius,
            "metres > 0",
        )
        for name, allowed, choices in (
            ("num_objects", f"integers from 1 to {MAX_OBJECTS}", range(1, MAX_OBJECTS + 1)),
            ("geometries", f"names from {list(GEOMETRIES)}", GEOMETRIES),
            ("backgrounds", f"names from {list(BACKGROUNDS)}", BACKGROUNDS),
        ):
            values = getattr(self, name)
            require(all(v in choices for v in values), name, list(values), f"a list of {allowed}")
        with config_group("planner"):
            check_planner_settings(self.planner)

    @property
    def first_seed(self) -> int:
        """Seed of the split's first episode (episode ``i`` uses ``first_seed + i``)."""
        return SPLIT_SEEDS[self.split]

    @classmethod
    def from_dicts(
        cls, eval_cfg: Mapping[str, Any], env_cfg: Mapping[str, Any]
    ) -> RearrangementSettings:
        """Builds settings from plain dicts: the ``eval`` group and the ``env`` group of a run.

        Raises:
            ConfigError: An unknown key, a wrong type or an out-of-range value, named.
        """
        task_names = {f.name for f in fields(TaskSettings)}
        own = {f.name for f in fields(cls)} - {"scene", "task"}
        check_keys(eval_cfg, own | task_names)
        task = settings_from(TaskSettings, {k: v for k, v in eval_cfg.items() if k in task_names})
        kwargs = {k: v for k, v in eval_cfg.items() if k in own}
        for key in ("methods", "num_objects", "geometries", "backgrounds"):
            if key in kwargs and kwargs[key] is None:
                kwargs[key] = ()
        scene = SceneSettings.from_mapping(env_cfg)
        return settings_from(cls, {"scene": scene, "task": task, **kwargs})

    def as_dict(self) -> dict[str, Any]:
        """Plain-container form (for JSON)."""
        out = asdict(self)
        out["planner"] = dict(self.planner)
        return out

    def conditions(self, generalization: bool = True) -> list[Condition]:
        """The comparison, then (if ``generalization``) the Table II cells and backgrounds."""
        out = [Condition(self.scene, "comparison", self.methods, self.episodes)]
        if not generalization:
            return out
        for geometry in self.geometries if self.scene.task == "blocks" else ("train",):
            for n in self.num_objects:
                scene = replace(self.scene, num_objects=n, geometry=geometry)
                out.append(
                    Condition(
                        scene, "generalization", (self.kinet_method,), self.generalization_episodes
                    )
                )
        for background in self.backgrounds:
            scene = replace(self.scene, background=background)
            out.append(
                Condition(
                    scene,
                    "background",
                    (self.kinet_method, "random"),
                    self.generalization_episodes,
                )
            )
        return out
