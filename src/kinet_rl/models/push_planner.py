"""Goal-conditioned push planning with any model that plans, for a real robot or the simulator."""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torch import Tensor

from kinet_rl.envs.settings import SceneSettings
from kinet_rl.keys import ACTION, GOAL_KP_POS, GOAL_PIXELS, KP_POS, PIXELS
from kinet_rl.planners.graph_mpc import GraphMPCPlanner
from kinet_rl.planners.world_model import PlanningInterface, PushWorldModelEnv

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
    """Plans the next push that brings the scene towards a goal, with any model that plans.

    Builds the model's ``torchrl.modules.WorldModel`` for its planning objective, wraps it in a
    :class:`~kinet_rl.planners.PushWorldModelEnv` and plans over it with a
    :class:`GraphMPCPlanner`. With no other argument it plans as the model's results were
    produced: the objective and planner settings stored with the model (``model.planning``,
    from its checkpoint) and the workspace of the scene it was trained on (``model.scene``).
    The planner's warm start (its previous plan shifted by one) is kept between calls and
    cleared when the goal changes or :meth:`reset` is called. A model trained on a robot's
    imported pushes takes the camera's own frames: they are cropped and resized as the import
    did (the checkpoint keeps the crop); frames already of the model's size pass unchanged.
    :meth:`next_pushes` plans for several scenes at once (one batched planner call; each scene
    keeps its own warm start).

    Example:
        >>> planner = PushPlanner(KINetWorldModel.from_checkpoint("runs/x/kinet.pt"))
        >>> push = planner.next_push(camera_image, goal_image)  # doctest: +SKIP
        >>> robot.push(push.start_xy_m, push.end_xy_m)  # doctest: +SKIP

    Args:
        model: A trained model (KINet, a baseline, the oracle: any ``PlanningInterface``).
        objective: Planning objective (default ``model.planning.objective``); one of
            ``model.capabilities.objectives``.
        planner: All :class:`GraphMPCPlanner` settings (default ``model.planning.planner``).
        workspace_half_size: Half the side of the square workspace, metres (default: that of
            ``model.scene``: the one its dataset stated (a robot's, imported), else its task's;
            0.20 blocks, 0.30 YCB).
        seed: Seeds the planner's sampling for reproducible pushes (None: global torch RNG); a
            sequence of seeds, one per scene of :meth:`next_pushes`, samples for each scene what
            a planner seeded with its seed alone would.
    """

    def __init__(
        self,
        model: PlanningInterface,
        objective: str | None = None,
        planner: Mapping[str, Any] | None = None,
        workspace_half_size: float | None = None,
        seed: int | Sequence[int] | None = None,
    ) -> None:
        scene: SceneSettings | None = model.scene
        if workspace_half_size is None:
            if scene is None:
                raise ValueError(
                    "The model does not say which scene it was trained on (it was not loaded from "
                    "a checkpoint); pass workspace_half_size= in metres (0.20 blocks, 0.30 YCB)."
                )
            workspace_half_size = scene.half_size
        if not workspace_half_size > 0:
            raise ValueError(f"workspace_half_size must be > 0 metres, got {workspace_half_size}.")
        self.objective = objective or model.planning.objective
        self.settings = dict(model.planning.planner if planner is None else planner)
        self.capabilities = model.capabilities
        self.scene = scene
        self.image_size = None if scene is None else scene.image_size
        self.world_model = model.world_model(self.objective)
        self.env = PushWorldModelEnv(self.world_model)
        self.planner = GraphMPCPlanner(
            self.env, generator=seeded_generators(seed, self.env.device), **self.settings
        )
        self.workspace_half_size = float(workspace_half_size)
        self._goal: Tensor | None = None
        self.last_state: TensorDictBase | None = None  # the encoded start state of the last plan

    def reset(self) -> None:
        """Forgets the warm-start plan (call at the start of a new task)."""
        self.planner.reset()

    def next_push(self, image: np.ndarray | Tensor, goal_image: np.ndarray | Tensor) -> Push:
        """The next push for the current ``image`` and the ``goal_image`` (both uint8 ``[H, W, 3]``)."""
        image = as_image_tensor(image, "image")
        goal = as_image_tensor(goal_image, "goal_image")
        return self.next_pushes(image.unsqueeze(0), goal.unsqueeze(0))[0]

    def next_pushes(self, images: Tensor, goal_images: Tensor) -> list[Push]:
        """The next push of each scene: ``images`` and ``goal_images`` uint8 ``[B, H, W, 3]``."""
        if not self.capabilities.plans_from_images:
            raise TypeError(
                f"This model plans from {list(self.capabilities.observes)}, not from images alone; "
                "call plan() with a tensordict of those entries and the goal."
            )
        for name, batch in (("images", images), ("goal_images", goal_images)):
            if batch.dim() != 4:
                raise ValueError(
                    f"{name} must be a batch of RGB images [B, H, W, 3], got shape "
                    f"{tuple(batch.shape)}; use next_push for one image."
                )
            as_image_tensor(batch[0], name)
        images, goal_images = self._model_images(images), self._model_images(goal_images)
        check_image_sizes(images[0], goal_images[0], self.image_size, self._source_size)
        if self._goal is None or not torch.equal(self._goal, goal_images):
            if self._goal is not None:
                logger.info("PushPlanner: new goal image; warm start cleared.")
            self.planner.reset()
            self._goal = goal_images.clone()
        observation = TensorDict(
            {PIXELS: images, GOAL_PIXELS: goal_images}, batch_size=images.shape[:1]
        )
        return [self._push(action) for action in self.plan(observation)]

    @property
    def _source_size(self) -> tuple[int, int] | None:
        return None if self.scene is None else self.scene.source_image_size

    def _model_images(self, frames: Tensor) -> Tensor:
        """Frames of the robot's camera cropped and resized as its import did (the model's
        scene says how); frames of other sizes unchanged."""
        if self.scene is None or self.scene.crop_box is None:
            return frames
        if tuple(frames.shape[1:3]) == (self.image_size, self.image_size):
            return frames  # already the model's images: no per-step copy on the planning path
        return torch.from_numpy(np.stack([self.scene.model_frame(f.numpy()) for f in frames.cpu()]))

    def plan(self, observation: TensorDictBase) -> Tensor:
        """Normalised pushes ``[*B, 4]`` for a ``[*B]`` tensordict of the model's observation and
        goal entries (``capabilities.observes`` and ``capabilities.goal``)."""
        state = self.world_model.observe(observation)
        self.last_state = state.cpu()
        return self.planner(state).get(ACTION).cpu()

    @property
    def last_keypoints(self) -> Tensor | None:
        """``[*B, K, 2]`` keypoints detected in the last image(s), for keypoint models."""
        return None if self.last_state is None else self.last_state.get(KP_POS, None)

    @property
    def last_goal_keypoints(self) -> Tensor | None:
        """``[*B, K, 2]`` keypoints detected in the goal image(s), for keypoint models."""
        return None if self.last_state is None else self.last_state.get(GOAL_KP_POS, None)

    def _push(self, action: Tensor) -> Push:
        action = action.double().clamp(-1.0, 1.0)
        metres = (action * self.workspace_half_size).tolist()
        return Push(
            start_xy_m=(metres[0], metres[1]),
            end_xy_m=(metres[2], metres[3]),
            normalised=tuple(action.tolist()),  # type: ignore[arg-type]
        )


def check_image_sizes(
    image: Tensor,
    goal: Tensor,
    model_size: int | None,
    source_size: tuple[int, int] | None = None,
) -> None:
    """Raises a ValueError naming the sizes if ``image`` ``[H, W, 3]`` is not the model's square
    size or ``goal`` is not the image's size (``source_size``: the robot camera's frame size,
    which the planner crops, named in the error)."""
    height, width = image.shape[:2]
    if model_size is not None and (height, width) != (model_size, model_size):
        camera = (
            ""
            if source_size is None
            else f", or the camera's {source_size[0]}x{source_size[1]} px frames (cropped as "
            "its import did)"
        )
        raise ValueError(
            f"The image is {width}x{height} px but the model was trained on {model_size}x"
            f"{model_size} px images; pass images of the model's camera and size{camera} (the "
            "command line resizes only when asked: --resize)."
        )
    if goal.shape != image.shape:
        raise ValueError(
            f"The goal image is {goal.shape[1]}x{goal.shape[0]} px but the current image is "
            f"{width}x{height} px; they must have the same size."
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
