"""The rearrangement task: episodes with reachable goals, controllers and ground-truth metrics.

How an episode is made (seeded by its ``seed`` alone):

1. ``make_dm_env(..., seed=seed)`` is reset: objects are placed at random, collision-free
   poses in the workspace (the environment's own initial-state distribution).
2. From that start, ``goal_pushes`` object-directed random pushes (the data-collection
   :class:`~kinet_rl.data.policy.RandomPushPolicy` with every push aimed at an object) are
   simulated; the resulting object positions and camera image are the goal. The goal is thus
   reachable by construction in ``goal_pushes`` pushes, well within ``T``.
3. A draw is rejected and redrawn (new placement) when the simulation goes unstable or the
   objects moved on average less than ``min_goal_distance`` metres.
4. The physics state of step 1 is restored and the controller gets ``num_steps`` pushes.

Metrics come from the simulator's ground truth, in metres: the mean over objects of the
distance between each object's centre and its own goal position, after every push (index 0 is
the start), and success: every object within ``success_threshold`` of its goal at the end.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import torch
from tensordict import TensorDict

from kinet_rl.control.oracle import AnalyticPushModelEnv
from kinet_rl.control.robot import PushPlanner
from kinet_rl.data.policy import RandomPushPolicy
from kinet_rl.envs import make_dm_env
from kinet_rl.envs.workspace import workspace_for
from kinet_rl.keys import ACTION, GOAL_OBJECT_POS, OBJECT_POS
from kinet_rl.planners import GraphMPCPlanner

#: Controllers compared by the evaluation.
METHODS = ("kinet_graph", "kinet_graph_distance", "kinet_keypoints", "random", "oracle")
#: Controllers of baseline models: MPC on the distance to the goal with the model's own state
#: (:class:`kinet_rl.baselines.model_env.BaselineMPCController`).
BASELINE_METHODS = ("model_mpc",)


@dataclass(frozen=True)
class SceneSettings:
    """Arguments of :func:`kinet_rl.envs.make_dm_env` that define an episode's scene."""

    task: str = "blocks"
    num_objects: int = 3
    camera: str = "top"
    image_size: int = 64
    geometry: str = "train"
    background: str = "fixed"


@dataclass(frozen=True)
class TaskSettings:
    """Rearrangement task and metric settings (see the module docstring)."""

    num_steps: int = 40
    goal_pushes: int = 4
    min_goal_distance: float = 0.03
    success_threshold: float = 0.03
    max_goal_tries: int = 20


@dataclass
class Episode:
    """A live episode: the dm_control env at its start state, and the goal."""

    env: Any  # kinet_rl.envs.PushEnvironment
    seed: int
    goal_pos: np.ndarray  # [N, 2] metres
    goal_pixels: np.ndarray  # [H, W, 3] uint8
    start: dict[str, np.ndarray]  # observation at the start state

    def close(self) -> None:
        """Releases the renderer."""
        self.env.close()


@dataclass
class EpisodeResult:
    """Ground-truth outcome of one controller on one episode."""

    method: str
    seed: int
    distances: np.ndarray  # [T + 1] mean object distance to goal, metres
    success: bool
    unstable: bool
    frames: list[np.ndarray] = field(default_factory=list)  # [H, W, 3] per step (if recorded)
    keypoints: list[np.ndarray] = field(default_factory=list)  # [K, 2] in [-1, 1] per step
    goal_pixels: np.ndarray | None = None
    goal_keypoints: np.ndarray | None = None


def mean_goal_distance(object_pos: np.ndarray, goal_pos: np.ndarray) -> float:
    """Mean over objects of ``|p_i - g_i|`` (metres), objects matched by identity."""
    return float(np.linalg.norm(np.asarray(object_pos) - np.asarray(goal_pos), axis=-1).mean())


def all_within(object_pos: np.ndarray, goal_pos: np.ndarray, threshold: float) -> bool:
    """Whether every object lies within ``threshold`` metres of its goal."""
    dist = np.linalg.norm(np.asarray(object_pos) - np.asarray(goal_pos), axis=-1)
    return bool((dist <= threshold).all())


def make_episode(scene: SceneSettings, task: TaskSettings, seed: int) -> Episode:
    """Builds the episode of ``seed``: random start, reachable goal (see the module docstring)."""
    env = make_dm_env(**vars(scene), seed=seed)
    half_size = workspace_for(scene.task).half_size
    goal_policy = RandomPushPolicy(half_size, object_push_prob=1.0)
    rng = np.random.default_rng([seed, 1])
    for _ in range(task.max_goal_tries):
        start = dict(env.reset().observation)
        start_state = env.physics.get_state().copy()
        obs = start
        for _ in range(task.goal_pushes):
            push = goal_policy.sample_push(rng, obs["object_pos"] / half_size)
            obs = env.step(push.astype(np.float32)).observation
        if env.task.unstable:
            continue
        if mean_goal_distance(obs["object_pos"], start["object_pos"]) < task.min_goal_distance:
            continue
        goal_pos, goal_pixels = obs["object_pos"].copy(), obs["pixels"].copy()
        env.physics.set_state(start_state)
        env.physics.forward()
        return Episode(env, seed, goal_pos, goal_pixels, start)
    env.close()
    raise RuntimeError(
        f"No usable goal for episode seed {seed} after {task.max_goal_tries} tries (unstable or "
        f"objects moved < {task.min_goal_distance} m); lower min_goal_distance or raise goal_pushes."
    )


class Controller(Protocol):
    """Chooses pushes for an episode."""

    def reset(self, episode: Episode) -> None:
        """Called once before the first push."""

    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        """The next push, ``[4]`` in ``[-1, 1]``."""


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
        self, scene: SceneSettings, planner: dict[str, Any], contact_radius: float, seed: int
    ) -> None:
        self.env = AnalyticPushModelEnv(
            scene.num_objects, workspace_for(scene.task).half_size, contact_radius
        )
        self.planner = GraphMPCPlanner(
            self.env, generator=torch.Generator().manual_seed(seed), **planner
        )
        self.goal = torch.zeros(scene.num_objects, 2)

    def reset(self, episode: Episode) -> None:
        """Sets the goal and clears the warm start."""
        self.goal = torch.as_tensor(episode.goal_pos, dtype=torch.float32)
        self.planner.reset()

    def act(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        """Plans on the true object positions."""
        pos = torch.as_tensor(observation["object_pos"], dtype=torch.float32)
        state = TensorDict({OBJECT_POS: pos, GOAL_OBJECT_POS: self.goal}, batch_size=[])
        return self.planner(state).get(ACTION).numpy()


class KINetController:
    """GraphMPC (``reward="graph"``) or keypoint-position MPC (``"keypoints"``) from images."""

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
        push = self.push_planner.next_push(observation["pixels"], self.goal_pixels)
        return np.asarray(push.normalised, dtype=np.float32)


def run_episode(
    episode: Episode,
    controller: Controller,
    method: str,
    task: TaskSettings,
    record: bool = False,
    on_step: Callable[[int], None] | None = None,
) -> EpisodeResult:
    """Runs ``task.num_steps`` pushes of ``controller`` from the episode's start.

    An unstable simulation ends the episode early; its last distance is carried to ``T``.
    With ``record`` the frames and (for KINet controllers) detected keypoints are kept.
    """
    obs = episode.start
    distances = [mean_goal_distance(obs["object_pos"], episode.goal_pos)]
    result = EpisodeResult(method, episode.seed, np.zeros(0), False, False)
    controller.reset(episode)
    for step in range(task.num_steps):
        action = np.clip(np.asarray(controller.act(obs), dtype=np.float32), -1.0, 1.0)
        if record:
            _record(result, controller, obs)
        obs = episode.env.step(action).observation
        distances.append(mean_goal_distance(obs["object_pos"], episode.goal_pos))
        if on_step is not None:
            on_step(step)
        if episode.env.task.unstable:
            result.unstable = True
            break
    if record:
        result.frames.append(obs["pixels"].copy())
        result.goal_pixels = episode.goal_pixels
        push_planner = getattr(controller, "push_planner", None)
        if push_planner is not None and push_planner.last_goal_keypoints is not None:
            result.goal_keypoints = push_planner.last_goal_keypoints.numpy()
    distances += [distances[-1]] * (task.num_steps + 1 - len(distances))
    result.distances = np.asarray(distances, dtype=np.float64)
    result.success = all_within(obs["object_pos"], episode.goal_pos, task.success_threshold)
    return result


def _record(result: EpisodeResult, controller: Controller, obs: dict[str, np.ndarray]) -> None:
    result.frames.append(obs["pixels"].copy())
    push_planner = getattr(controller, "push_planner", None)
    if push_planner is not None and push_planner.last_keypoints is not None:
        result.keypoints.append(push_planner.last_keypoints.numpy())
