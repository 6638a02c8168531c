"""Goal-conditioned push planning from camera images, for a real robot or the simulator."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor

from kinet_rl.keys import ACTION, GOAL_KP_POS, KP_POS
from kinet_rl.models.model_env import GraphDistanceReward, KINetModelEnv, KINetReward
from kinet_rl.models.world_model import KINetWorldModel
from kinet_rl.planners.graph_mpc import GraphMPCPlanner

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Push:
    """One planned push.

    Attributes:
        start_xy_m: Push start ``(x, y)`` in metres, table frame (origin at the workspace centre,
            +x right and +y up in the top camera image).
        end_xy_m: Push end ``(x, y)`` in metres, table frame.
        normalised: ``(start x, start y, end x, end y)`` in ``[-1, 1]`` (metres / half size), the
            action the simulator and the model use.
    """

    start_xy_m: tuple[float, float]
    end_xy_m: tuple[float, float]
    normalised: tuple[float, float, float, float]

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly form."""
        return {
            "start_xy_m": list(self.start_xy_m),
            "end_xy_m": list(self.end_xy_m),
            "normalised": list(self.normalised),
        }


def as_image_tensor(image: np.ndarray | Tensor, name: str = "image") -> Tensor:
    """An ``[H, W, 3]`` uint8 image as a tensor; clear errors for anything else."""
    tensor = image if isinstance(image, Tensor) else torch.from_numpy(np.array(image))  # a copy
    if tensor.dim() != 3 or tensor.shape[-1] != 3:
        raise ValueError(
            f"{name} must be an RGB image [H, W, 3], got shape {tuple(tensor.shape)}; drop any "
            "alpha channel and pass one image at a time."
        )
    if tensor.dtype != torch.uint8:
        raise TypeError(f"{name} must be uint8 (0-255), got {tensor.dtype}; convert it first.")
    return tensor


class PushPlanner:
    """Plans the next push that brings the scene in ``image`` towards the one in ``goal_image``.

    Wraps a :class:`GraphMPCPlanner` over a :class:`KINetModelEnv`; the planner's warm start
    (its previous plan shifted by one) is kept between calls and cleared when the goal image
    changes or :meth:`reset` is called. Images must come from the camera, view and resolution
    the model was trained on. :meth:`next_pushes` plans for several scenes at once (one batched
    planner call; each scene keeps its own warm start).

    Example:
        >>> planner = PushPlanner(KINetWorldModel.from_checkpoint("runs/x/kinet.pt"), 0.20)
        >>> push = planner.next_push(camera_image, goal_image)  # doctest: +SKIP
        >>> robot.push(push.start_xy_m, push.end_xy_m)  # doctest: +SKIP

    Args:
        model: A trained KINet world model.
        workspace_half_size: Half the side of the square workspace, metres (0.20 blocks, 0.30 YCB).
        reward: The planning objective (default :class:`GraphDistanceReward`, GraphMPC on the
            node-embedding distance); see :class:`KINetModelEnv`.
        seed: Seeds the planner's sampling for reproducible pushes (None: global torch RNG); a
            sequence of seeds, one per scene of :meth:`next_pushes`, samples for each scene what
            a planner seeded with its seed alone would.
        **planner_kwargs: :class:`GraphMPCPlanner` settings (``planning_horizon``, ...).
    """

    def __init__(
        self,
        model: KINetWorldModel,
        workspace_half_size: float,
        reward: KINetReward | None = None,
        seed: int | Sequence[int] | None = None,
        **planner_kwargs: Any,
    ) -> None:
        if not workspace_half_size > 0:
            raise ValueError(f"workspace_half_size must be > 0 metres, got {workspace_half_size}.")
        model.eval()
        self.env = KINetModelEnv(model, GraphDistanceReward() if reward is None else reward)
        self.planner = GraphMPCPlanner(
            self.env, generator=seeded_generators(seed, self.env.device), **planner_kwargs
        )
        self.workspace_half_size = float(workspace_half_size)
        self._goal: Tensor | None = None
        self.last_keypoints: Tensor | None = None  # [*B, K, 2] detected in the last image(s)
        self.last_goal_keypoints: Tensor | None = None  # [*B, K, 2] detected in the goal image(s)

    def reset(self) -> None:
        """Forgets the warm-start plan (call at the start of a new task)."""
        self.planner.reset()

    def next_push(self, image: np.ndarray | Tensor, goal_image: np.ndarray | Tensor) -> Push:
        """The next push for the current ``image`` and the ``goal_image`` (both uint8 ``[H, W, 3]``)."""
        image = as_image_tensor(image, "image")
        goal = as_image_tensor(goal_image, "goal_image")
        return self._plan(image, goal)[0]

    def next_pushes(self, images: Tensor, goal_images: Tensor) -> list[Push]:
        """The next push of each scene: ``images`` and ``goal_images`` uint8 ``[B, H, W, 3]``."""
        for name, batch in (("images", images), ("goal_images", goal_images)):
            if batch.dim() != 4:
                raise ValueError(
                    f"{name} must be a batch of RGB images [B, H, W, 3], got shape "
                    f"{tuple(batch.shape)}; use next_push for one image."
                )
            as_image_tensor(batch[0], name)
        return self._plan(images, goal_images)

    def _plan(self, images: Tensor, goals: Tensor) -> list[Push]:
        if self._goal is None or not torch.equal(self._goal, goals):
            if self._goal is not None:
                logger.info("PushPlanner: new goal image; warm start cleared.")
            self.planner.reset()
            self._goal = goals.clone()
        state = self.env.observe(images, goals)
        self.last_keypoints = state.get(KP_POS).cpu()
        self.last_goal_keypoints = state.get(GOAL_KP_POS).cpu()
        actions = self.planner(state).get(ACTION).cpu().double().clamp(-1.0, 1.0)
        return [self._push(action) for action in actions.reshape(-1, 4)]

    def _push(self, action: Tensor) -> Push:
        metres = (action * self.workspace_half_size).tolist()
        return Push(
            start_xy_m=(metres[0], metres[1]),
            end_xy_m=(metres[2], metres[3]),
            normalised=tuple(action.tolist()),  # type: ignore[arg-type]
        )


def seeded_generators(
    seed: int | Sequence[int] | None, device: torch.device | str = "cpu"
) -> torch.Generator | list[torch.Generator] | None:
    """A planner's ``generator`` argument: None, one seeded generator, or one per seed."""
    if seed is None:
        return None
    if isinstance(seed, int):
        return torch.Generator(device).manual_seed(seed)
    return [torch.Generator(device).manual_seed(s) for s in seed]
