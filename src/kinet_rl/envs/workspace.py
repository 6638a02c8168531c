"""Geometry of the square pushing workspace on the table.

The table frame has its origin at the centre of the table top, +x to the right of the top
camera image, +y up in it, +z up. Actions are push start and end points normalised to the
workspace: ``a = xy_m / half_size`` so that ``[-1, 1]`` spans the workspace.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

import numpy as np
import torch

ArrayT = TypeVar("ArrayT", np.ndarray, torch.Tensor)

__all__ = ["Workspace", "workspace_for", "WORKSPACES"]


@dataclass(frozen=True)
class Workspace:
    """A square workspace centred on the table origin.

    Args:
        half_size: half the side of the square workspace, metres.
        table_height: height of the table top in the world frame, metres.
        table_half_size: half the side of the (square) table top, metres; objects whose
            centre leaves it have fallen off the table.
    """

    half_size: float
    table_height: float = 0.0
    table_half_size: float = 0.0

    def __post_init__(self) -> None:
        if self.half_size <= 0:
            raise ValueError(f"Workspace.half_size must be positive, got {self.half_size}.")
        if self.table_half_size and self.table_half_size < self.half_size:
            raise ValueError(
                f"Workspace.table_half_size ({self.table_half_size}) must be at least "
                f"half_size ({self.half_size}) so that the workspace lies on the table."
            )

    def to_action(self, xy_m: ArrayT) -> ArrayT:
        """Map table-frame metres ``[..., 2*k]`` to normalised action units (no clipping)."""
        return xy_m / self.half_size

    def to_metres(self, action: ArrayT) -> ArrayT:
        """Map normalised action units ``[..., 2*k]`` in [-1, 1] to table-frame metres."""
        return action * self.half_size

    def push_endpoints(self, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Push start and end ``[2]`` in metres from a 4-d action, clipped to [-1, 1].

        Raises:
            ValueError: the action is not 4 finite numbers.
        """
        action = np.asarray(action, dtype=float).reshape(-1)
        if action.shape != (4,) or not np.all(np.isfinite(action)):
            raise ValueError(
                f"A push action must be 4 finite numbers (start x, y, end x, y) in [-1, 1], got {action}."
            )
        start, end = self.to_metres(np.clip(action, -1.0, 1.0)).reshape(2, 2)
        return start, end


#: Workspace of each task. Blocks are 3-9 cm, YCB objects up to 21 cm across, so the YCB
#: workspace is larger to fit 5 of them. The YCB table is large enough to fill the side
#: camera's image (``scene.CAMERA_FRAMINGS``), so objects pushed past the workspace stay on it.
WORKSPACES: dict[str, Workspace] = {
    "blocks": Workspace(half_size=0.20, table_height=0.0, table_half_size=0.30),
    "ycb": Workspace(half_size=0.30, table_height=0.0, table_half_size=0.85),
}


def workspace_for(task: str) -> Workspace:
    """Return the :class:`Workspace` of ``task`` (``"blocks"`` or ``"ycb"``)."""
    try:
        return WORKSPACES[task]
    except KeyError:
        raise ValueError(f"Unknown task {task!r}; choose one of {sorted(WORKSPACES)}.") from None
