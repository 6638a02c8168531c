"""The comparison rows: one registry of every model of the paper's tables, and loading any of them.

A :class:`Row` names a model of the comparison (KINet and its ablations, the baselines) with the
experiment that trains it, its label, its model class and how its MPC rows plan. The tables,
the comparison markdown and the entry points read rows from here; nothing else decides by model
class. :func:`load_trained_model` loads any row's checkpoint (a ``.pt`` file or a model folder)
by the format it stores.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

from kinet_rl.atomic import CheckpointError
from kinet_rl.baselines import (
    FullStateInteractionModel,
    ImageForwardInverseModel,
    ImageForwardModel,
    ObjectInteractionModel,
    VCDNWorldModel,
    VisualInteractionModel,
)
from kinet_rl.models.checkpointing import ConfigCheckpointMixin, stored_entries
from kinet_rl.models.world_model import KINetWorldModel


@dataclass(frozen=True)
class Row:
    """A model of the comparison tables.

    Attributes:
        name: Its key in ``conf/tables/*.yaml`` (``models``) and in the tables' JSON.
        label: How the tables name it.
        experiment_suffix: Its experiment is ``conf/exp/<task>_<camera>view<suffix>.yaml``.
        model: Its model class.
        method: The rearrangement method of its MPC rows: None for the experiment's validated
            KINet method (``eval.kinet_method``, a planning objective chosen on validation
            episodes), ``model_mpc`` for a baseline's own distance to the goal.
        planner_label: How the MPC table names its planner (None: the method's label).
        floor: Table I's detector floor is measured with this row's keypoint detector.
    """

    name: str
    label: str
    experiment_suffix: str
    model: type[ConfigCheckpointMixin]
    method: str | None
    planner_label: str | None = None
    floor: bool = False


_GT = "MPC on GT goal distance"
_FEATURES = "MPC on goal-image feature distance"

#: Every comparison row, by name, in the tables' order.
ROWS: dict[str, Row] = {
    row.name: row
    for row in (
        Row("kinet", "KINet", "", KINetWorldModel, None, floor=True),
        Row("kinet_determ", "KINet-determ", "_determ", KINetWorldModel, None, floor=True),
        Row("kinet_no_ctr", "KINet-no-ctr", "_no_ctr", KINetWorldModel, None, floor=True),
        Row("forw", "Forw", "_forw", ImageForwardModel, "model_mpc", _FEATURES),
        Row("forwinv", "ForwInv", "_forwinv", ImageForwardInverseModel, "model_mpc", _FEATURES),
        Row("in", "IN (GT state)", "_in", ObjectInteractionModel, "model_mpc", _GT),
        Row(
            "in_full",
            "IN-full (GT pos, yaw, shape)",
            "_in_full",
            FullStateInteractionModel,
            "model_mpc",
            _GT,
        ),
        Row(
            "visin", "VisIN (GT state + image)", "_visin", VisualInteractionModel, "model_mpc", _GT
        ),
        Row(
            "vcdn",
            "V-CDN",
            "_vcdn",
            VCDNWorldModel,
            "model_mpc",
            "MPC on goal-image keypoint distance",
        ),
    )
}


def load_trained_model(path: str | os.PathLike) -> Any:
    """The model of any row's checkpoint (KINet or a baseline), a ``.pt`` file or a model folder
    (``save_pretrained``), chosen by the format it stores, in eval mode."""
    formats = {row.model.checkpoint_format: row.model for row in ROWS.values()}
    stored = stored_entries(path)["format"]
    model_class = formats.get(stored)
    if model_class is None:
        raise CheckpointError(
            f"Checkpoint {path} has format {stored!r}, which no model of kinet_rl reads "
            f"(formats: {sorted(formats)}); pass a kinet.pt or model.pt of a run, or a model "
            "folder."
        )
    model: Any = model_class.from_checkpoint(path)
    return model.eval()
