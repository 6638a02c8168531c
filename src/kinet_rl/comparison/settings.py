"""The settings of the comparison tables (the ``tables`` config group): rows, variants,
cameras, MPC budgets, seeds."""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from kinet_rl.config_schema import check_arguments, conform, require, settings_from
from kinet_rl.planners.graph_mpc import CODE_ARGUMENTS, GraphMPCPlanner
from kinet_rl.rearrangement.methods import METHODS
from kinet_rl.rows import ROWS, Row

#: Row labels of the tables: the comparison rows, random pushes and the oracle.
LABELS = {
    **{name: row.label for name, row in ROWS.items()},
    "random": METHODS["random"].label,
    "oracle": METHODS["oracle"].label,
}
#: The cameras of the tables' rows.
CAMERAS = ("top", "side")
#: The tables' scenes: ``task`` of the rows' experiments, and how the tables name it.
TASKS = {"blocks": "BlockObjs", "ycb": "YCBObjs"}
#: What a planner budget's or a variant's name may be (it names files, e.g. ``tables_mpc_64x3.json``).
BUDGET_NAME = re.compile(r"[\w.-]+")
#: Keys of an ``mpc_budgets`` entry besides its planner settings: the MPC table's episodes per
#: row (default: ``eval.episodes``) and its rows (default: every model).
BUDGET_KEYS = ("episodes", "models")


@dataclass(frozen=True)
class Variant:
    """A row beyond the registry's (``tables.variants``): a model of :data:`~kinet_rl.rows.ROWS`
    trained with extra overrides, e.g. KINet with K = 3 keypoints.

    Its run is ``<out>/<experiment>_<name>`` (the experiment of ``model``). It shares the model's
    experiment, ``model_overrides``, planner and detector floor.

    Attributes:
        model: The registry row it varies.
        label: How the tables name it.
        overrides: Hydra overrides after the model's, of its training and of its MPC scene
            (e.g. ``keypoints=3``, ``env.image_size=128``).
        train_overrides: Overrides of its training only; its MPC episodes keep the table's scene
            (e.g. trained on random textures, ``env.background=random``, and planned on the
            table's fixed background like every other row).
    """

    model: str
    label: str
    overrides: tuple[str, ...] = ()
    train_overrides: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        require(self.model in ROWS, "model", self.model, f"one of {list(ROWS)}")


@dataclass(frozen=True)
class TablesSettings:
    """The ``tables`` config group (``conf/tables/<scale>.yaml``; ``conf/tables.yaml`` and each
        file document its keys).

        ``mpc_budgets`` maps an MPC table's name to planner settings that override each row's eval
        planner (their keys and types are checked here, their ranges by
    :func:`kinet_rl.tables.check_rows`), plus
        optionally ``episodes`` and ``models`` (:data:`BUDGET_KEYS`); a budget set to null is
        dropped (so that a config extending another can drop one), and no budget at all leaves
        Table I alone. ``variants`` maps a row name to a :class:`Variant`; ``models`` may name
        both. ``mpc_seeds`` are the training seeds whose models plan (default: the first seed).

        Raises:
            ConfigError: A model, camera, seed, budget or variant that no row can have, named.
    """

    scale: str
    models: tuple[str, ...]
    cameras: tuple[str, ...]
    mpc_camera: str
    generalization_models: tuple[str, ...]
    seeds: tuple[int, ...]
    forward_horizons: tuple[int, ...]
    forward_sequences: int
    mpc_budgets: Mapping[str, Any]  # name -> a mapping, or None (dropped)
    overrides: tuple[str, ...] = ()
    task: str = "blocks"
    model_overrides: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    camera_overrides: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    variants: Mapping[str, Any] = field(default_factory=dict)
    mpc_seeds: tuple[int, ...] | None = None
    eval: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # Normalised once (a frozen dataclass: replace() passes these forms back in).
        variants = {
            name: v if isinstance(v, Variant) else settings_from(Variant, v, f"variants.{name}")
            for name, v in self.variants.items()
        }
        object.__setattr__(self, "variants", variants)
        budgets = {
            name: dict(conform(f"mpc_budgets.{name}", b, Mapping[str, Any]))
            for name, b in self.mpc_budgets.items()
            if b is not None
        }
        object.__setattr__(self, "mpc_budgets", budgets)
        self._check_variants()
        for name, choices, least in (
            ("models", tuple(self.rows), 1),
            ("cameras", CAMERAS, 1),
            ("generalization_models", self.models, 0),
            ("model_overrides", tuple(ROWS), 0),
            ("camera_overrides", self.cameras, 0),
        ):
            values = list(getattr(self, name))
            require(
                len(values) >= least and set(values) <= set(choices),
                name,
                values,
                f"{'a non-empty list' if least else 'a list'} of names from {list(choices)}",
            )
        require(self.mpc_camera in self.cameras, "mpc_camera", self.mpc_camera, "one of cameras")
        require(self.task in TASKS, "task", self.task, f"one of {list(TASKS)}")
        for name, low in (("seeds", 0), ("forward_horizons", 1)):
            values = list(getattr(self, name))
            require(
                bool(values) and min(values) >= low,
                name,
                values,
                f"a non-empty list of integers of at least {low}",
            )
        require(
            self.forward_sequences >= 1,
            "forward_sequences",
            self.forward_sequences,
            "an integer of at least 1",
        )
        mpc_seeds = list(self.mpc_seeds or ())
        require(
            self.mpc_seeds is None or (bool(mpc_seeds) and set(mpc_seeds) <= set(self.seeds)),
            "mpc_seeds",
            mpc_seeds,
            f"null (the first seed) or a non-empty list of seeds from {list(self.seeds)}",
        )
        self._check_budgets()

    def _check_variants(self) -> None:
        suffixes = {row.experiment_suffix for row in ROWS.values()}
        for name, variant in self.variants.items():
            suffix = f"{ROWS[variant.model].experiment_suffix}_{name}"
            require(
                name not in ROWS
                and BUDGET_NAME.fullmatch(name) is not None
                and suffix not in suffixes
                and re.fullmatch(r"seed\d+", name) is None,
                "variants",
                name,
                "a name (letters, digits, '_', '-', '.') that is no row of the registry "
                f"({list(ROWS)}) and gives its run a folder of its own",
            )

    def _check_budgets(self) -> None:
        require(
            all(BUDGET_NAME.fullmatch(n) for n in self.mpc_budgets),
            "mpc_budgets",
            dict(self.mpc_budgets),
            "a mapping from names (letters, digits, '_', '-', '.'; they name files) to "
            "planner settings, e.g. {64x3: {num_candidates: 64, optim_steps: 3, top_k: 8}}",
        )
        for name, budget in self.mpc_budgets.items():  # keys and types; ranges: check_rows
            group = f"mpc_budgets.{name}"
            planner = {k: v for k, v in budget.items() if k not in BUDGET_KEYS}
            check_arguments(GraphMPCPlanner, planner, group, exclude=CODE_ARGUMENTS)
            episodes = conform(f"{group}.episodes", budget.get("episodes"), int | None)
            require(episodes is None or episodes >= 1, f"{group}.episodes", episodes, "at least 1")
            models = conform(f"{group}.models", budget.get("models"), list[str] | None)
            require(
                models is None or (bool(models) and set(models) <= set(self.models)),
                f"{group}.models",
                models,
                f"a non-empty list of names from models ({list(self.models)}) or null (every "
                "model)",
            )
        first = next(iter(self.mpc_budgets), None)
        planned = [] if first is None else self.budget_models(first)
        require(
            set(self.generalization_models) <= set(planned),
            "generalization_models",
            list(self.generalization_models),
            "models that plan at the first of mpc_budgets (Table II runs at it)"
            + ("" if first else "; there is none, so an empty list"),
        )

    @property
    def rows(self) -> dict[str, Row]:
        """Every row these tables may have, by name: the registry's and the variants."""
        variants = {
            name: replace(ROWS[v.model], name=name, label=v.label)
            for name, v in self.variants.items()
        }
        return {**ROWS, **variants}

    @property
    def planning_seeds(self) -> tuple[int, ...]:
        """The training seeds whose models plan (``mpc_seeds``, default the first seed)."""
        return tuple(self.mpc_seeds) if self.mpc_seeds is not None else self.seeds[:1]

    def base_model(self, name: str) -> str:
        """The registry row of a row: itself, or a variant's model."""
        return self.variants[name].model if name in self.variants else name

    def budget_planner(self, budget: str) -> dict[str, Any]:
        """The planner settings of an MPC table (its entry without :data:`BUDGET_KEYS`)."""
        return {k: v for k, v in self.mpc_budgets[budget].items() if k not in BUDGET_KEYS}

    def budget_models(self, budget: str) -> list[str]:
        """The rows of an MPC table, in the order of ``models``."""
        chosen = self.mpc_budgets[budget].get("models")
        return [m for m in self.models if chosen is None or m in chosen]

    @classmethod
    def from_container(cls, values: Mapping[str, Any]) -> TablesSettings:
        """Settings from the resolved ``tables`` group."""
        return settings_from(cls, values, "tables")
