"""Controllers of the rearrangement evaluation: they choose the pushes of a batch of episodes.

A controller plans for ``B`` episodes at once (``B = 1`` for one at a time): one seed per
episode, one observation per episode at each step, one batched planner call for all of them.
Episode ``i`` samples from its own seeded generator, so it gets the pushes it would get alone (up
to floating-point rounding of the batched arithmetic).

Learned-model controllers see only what a real robot would: KINet's sees camera images; the
GT-state baselines (IN, IN-full, VisIN) and the oracle see the simulator's object state, which is
what makes them ceilings rather than peers.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict
from torch import Tensor, nn

from kinet_rl.baselines.model_env import ObjectModelEnv, make_baseline_env
from kinet_rl.baselines.oracle import AnalyticPushModelEnv
from kinet_rl.envs.settings import SceneSettings
from kinet_rl.envs.workspace import workspace_for
from kinet_rl.keys import ACTION, GOAL_OBJECT_POS, OBJECT_POS, PIXELS
from kinet_rl.models.push_planner import PushPlanner, seeded_generators
from kinet_rl.planners.graph_mpc import GraphMPCPlanner
from kinet_rl.rearrangement.episodes import Episode

Observations = Sequence[Mapping[str, np.ndarray]]


def stacked(observations: Observations, key: str, dtype: torch.dtype | None = None) -> Tensor:
    """``key`` of every episode's observation, stacked into a ``[B, ...]`` tensor."""
    return torch.as_tensor(np.stack([obs[key] for obs in observations]), dtype=dtype)


class RandomController:
    """Uniform random pushes: start and end uniform in the workspace."""

    def __init__(self, seeds: Sequence[int]) -> None:
        self.rngs = [np.random.default_rng(seed) for seed in seeds]

    def reset(self, episodes: Sequence[Episode]) -> None:
        """Nothing to reset."""

    def act(self, observations: Observations) -> np.ndarray:
        """A uniform random push per episode, ``[B, 4]``."""
        return np.stack([rng.uniform(-1.0, 1.0, 4) for rng in self.rngs])


class OracleController:
    """MPC (:class:`GraphMPCPlanner`) on ground-truth object positions with an analytic push model."""

    def __init__(
        self,
        scene: SceneSettings,
        planner: Mapping[str, Any],
        contact_radius: float,
        seeds: Sequence[int],
    ) -> None:
        self.env = AnalyticPushModelEnv(
            scene.num_objects, workspace_for(scene.task).half_size, contact_radius
        )
        self.planner = GraphMPCPlanner(
            self.env, generator=seeded_generators(list(seeds)), **dict(planner)
        )
        self.goal = torch.zeros(len(seeds), scene.num_objects, 2)

    def reset(self, episodes: Sequence[Episode]) -> None:
        """Sets the goals and clears the warm start."""
        self.goal = torch.as_tensor(np.stack([e.goal_pos for e in episodes]), dtype=torch.float32)
        self.planner.reset()

    def act(self, observations: Observations) -> np.ndarray:
        """Plans on the true object positions."""
        pos = stacked(observations, OBJECT_POS, torch.float32)
        state = TensorDict({OBJECT_POS: pos, GOAL_OBJECT_POS: self.goal}, batch_size=pos.shape[:1])
        return self.planner(state).get(ACTION).numpy()


class KINetController:
    """GraphMPC or keypoint-position MPC from images, through a :class:`PushPlanner`."""

    def __init__(self, push_planner: PushPlanner) -> None:
        self.push_planner = push_planner
        self.goal_pixels: Tensor | None = None

    def reset(self, episodes: Sequence[Episode]) -> None:
        """Sets the goal images and clears the warm start."""
        self.goal_pixels = torch.from_numpy(np.stack([e.goal_pixels for e in episodes]))
        self.push_planner.reset()

    def act(self, observations: Observations) -> np.ndarray:
        """Plans on the keypoints of the current images."""
        if self.goal_pixels is None:
            raise RuntimeError("KINetController.act called before reset(episodes); reset it first.")
        pushes = self.push_planner.next_pushes(stacked(observations, PIXELS), self.goal_pixels)
        return np.asarray([push.normalised for push in pushes], dtype=np.float32)


class BaselineMPCController:
    """MPC on the distance to the goal with a baseline model.

    "For all baseline models, we perform MPC directly on the distance to the goal" (KINet, Sec. 5):
    IN/IN-full/VisIN plan on the true object state (IN-full: also yaw and shape) towards the
    true goal positions; Forw/ForwInv plan on image features towards the goal image's feature;
    V-CDN on its keypoints towards the goal image's keypoints.

    Args:
        model: A baseline model (see :func:`~kinet_rl.baselines.make_baseline_env`).
        planner: :class:`GraphMPCPlanner` settings.
        seeds: Seeds of the planner's sampling, one per episode.
    """

    def __init__(self, model: nn.Module, planner: Mapping[str, Any], seeds: Sequence[int]) -> None:
        self.env = make_baseline_env(model)
        self.planner = GraphMPCPlanner(
            self.env, generator=seeded_generators(list(seeds)), **dict(planner)
        )
        self.episodes: Sequence[Episode] = ()

    def reset(self, episodes: Sequence[Episode]) -> None:
        """Keeps the episodes' goals and clears the warm start."""
        self.episodes = episodes
        self.planner.reset()

    def act(self, observations: Observations) -> np.ndarray:
        """Plans from the current observations (``pixels``, ``object_pos``; IN-full also
        ``object_yaw``, ``object_shape``)."""
        if not self.episodes:
            raise RuntimeError(
                "BaselineMPCController.act called before reset(episodes); reset it first."
            )
        pixels = stacked(observations, PIXELS)
        if isinstance(self.env, ObjectModelEnv):
            pos = stacked(observations, OBJECT_POS, torch.float32)
            goal = torch.as_tensor(
                np.stack([e.goal_pos for e in self.episodes]), dtype=torch.float32
            )
            extra = {key: stacked(observations, key) for key in self.env.model.state_keys}
            state = self.env.observe(pixels, pos, goal, **extra)
        else:
            goal_pixels = torch.from_numpy(np.stack([e.goal_pixels for e in self.episodes]))
            state = self.env.observe(pixels, goal_pixels)
        return self.planner(state).get(ACTION).cpu().numpy()
