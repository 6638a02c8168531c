"""Controllers of the rearrangement evaluation: they choose the pushes of an episode.

Learned-model controllers see only what a real robot would: KINet's sees camera images; the
GT-state baselines (IN, VisIN) and the oracle see the simulator's object positions, which is
what makes them ceilings rather than peers.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict
from torch import nn

from kinet_rl.baselines.model_env import ObjectModelEnv, make_baseline_env
from kinet_rl.baselines.oracle import AnalyticPushModelEnv
from kinet_rl.envs.settings import SceneSettings
from kinet_rl.envs.workspace import workspace_for
from kinet_rl.keys import ACTION, GOAL_OBJECT_POS, OBJECT_POS, PIXELS
from kinet_rl.models.push_planner import PushPlanner
from kinet_rl.planners.graph_mpc import GraphMPCPlanner
from kinet_rl.rearrangement.episodes import Episode


class RandomController:
    """Uniform random pushes: start and end uniform in the workspace."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def reset(self, episode: Episode) -> None:
        """Nothing to reset."""

    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        """A uniform random push."""
        return self.rng.uniform(-1.0, 1.0, 4)


class OracleController:
    """MPC (:class:`GraphMPCPlanner`) on ground-truth object positions with an analytic push model."""

    def __init__(
        self, scene: SceneSettings, planner: Mapping[str, Any], contact_radius: float, seed: int
    ) -> None:
        self.env = AnalyticPushModelEnv(
            scene.num_objects, workspace_for(scene.task).half_size, contact_radius
        )
        self.planner = GraphMPCPlanner(
            self.env, generator=torch.Generator().manual_seed(seed), **dict(planner)
        )
        self.goal = torch.zeros(scene.num_objects, 2)

    def reset(self, episode: Episode) -> None:
        """Sets the goal and clears the warm start."""
        self.goal = torch.as_tensor(episode.goal_pos, dtype=torch.float32)
        self.planner.reset()

    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        """Plans on the true object positions."""
        pos = torch.as_tensor(observation[OBJECT_POS], dtype=torch.float32)
        state = TensorDict({OBJECT_POS: pos, GOAL_OBJECT_POS: self.goal}, batch_size=[])
        return self.planner(state).get(ACTION).numpy()


class KINetController:
    """GraphMPC or keypoint-position MPC from images, through a :class:`PushPlanner`."""

    def __init__(self, push_planner: PushPlanner) -> None:
        self.push_planner = push_planner
        self.goal_pixels: np.ndarray | None = None

    def reset(self, episode: Episode) -> None:
        """Sets the goal image and clears the warm start."""
        self.goal_pixels = episode.goal_pixels
        self.push_planner.reset()

    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        """Plans on the keypoints of the current image."""
        if self.goal_pixels is None:
            raise RuntimeError("KINetController.act called before reset(episode); reset it first.")
        push = self.push_planner.next_push(observation[PIXELS], self.goal_pixels)
        return np.asarray(push.normalised, dtype=np.float32)


class BaselineMPCController:
    """MPC on the distance to the goal with a baseline model.

    "For all baseline models, we perform MPC directly on the distance to the goal" (KINet, Sec. 5):
    IN/VisIN plan on the true object positions towards the true goal positions; Forw/ForwInv
    plan on image features towards the goal image's feature; V-CDN on its keypoints towards the
    goal image's keypoints.

    Args:
        model: A baseline model (see :func:`~kinet_rl.baselines.make_baseline_env`).
        planner: :class:`GraphMPCPlanner` settings.
        seed: Seed of the planner's sampling.
    """

    def __init__(self, model: nn.Module, planner: Mapping[str, Any], seed: int) -> None:
        self.env = make_baseline_env(model)
        self.planner = GraphMPCPlanner(
            self.env, generator=torch.Generator().manual_seed(seed), **dict(planner)
        )
        self.episode: Episode | None = None

    def reset(self, episode: Episode) -> None:
        """Keeps the episode's goal and clears the warm start."""
        self.episode = episode
        self.planner.reset()

    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        """Plans from the current observation (``pixels``, ``object_pos``)."""
        if self.episode is None:
            raise RuntimeError(
                "BaselineMPCController.act called before reset(episode); reset it first."
            )
        pixels = torch.from_numpy(np.array(observation[PIXELS]))
        if isinstance(self.env, ObjectModelEnv):
            pos = torch.as_tensor(observation[OBJECT_POS], dtype=torch.float32)
            goal = torch.as_tensor(self.episode.goal_pos, dtype=torch.float32)
            state = self.env.observe(pixels, pos, goal)
        else:
            state = self.env.observe(pixels, torch.from_numpy(np.array(self.episode.goal_pixels)))
        return self.planner(state).get(ACTION).cpu().numpy()
