"""The rearrangement task: episodes with reachable goals, and running a controller on one.

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
Beside them, the metric a real robot can measure: the SSIM of the camera image to the goal
image after every push (:func:`kinet_rl.evaluation.similarity.ssim`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from kinet_rl.data.policy import RandomPushPolicy
from kinet_rl.envs import make_dm_env
from kinet_rl.envs.settings import SceneSettings
from kinet_rl.envs.workspace import workspace_for
from kinet_rl.evaluation.similarity import ssim
from kinet_rl.keys import OBJECT_POS, PIXELS
from kinet_rl.rearrangement.results import EpisodeResult
from kinet_rl.rearrangement.settings import TaskSettings


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


def mean_goal_distance(object_pos: np.ndarray, goal_pos: np.ndarray) -> float:
    """Mean over objects of ``|p_i - g_i|`` (metres), objects matched by identity."""
    return float(np.linalg.norm(np.asarray(object_pos) - np.asarray(goal_pos), axis=-1).mean())


def all_within(object_pos: np.ndarray, goal_pos: np.ndarray, threshold: float) -> bool:
    """Whether every object lies within ``threshold`` metres of its goal."""
    dist = np.linalg.norm(np.asarray(object_pos) - np.asarray(goal_pos), axis=-1)
    return bool((dist <= threshold).all())


def goal_similarity(observation: dict[str, np.ndarray], episode: Episode) -> float:
    """SSIM of the observation's camera image to the episode's goal image."""
    return float(ssim(observation[PIXELS], episode.goal_pixels))


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
            push = goal_policy.sample_push(rng, obs[OBJECT_POS] / half_size)
            obs = env.step(push.astype(np.float32)).observation
        if env.task.unstable:
            continue
        if mean_goal_distance(obs[OBJECT_POS], start[OBJECT_POS]) < task.min_goal_distance:
            continue
        goal_pos, goal_pixels = obs[OBJECT_POS].copy(), obs[PIXELS].copy()
        env.physics.set_state(start_state)
        env.physics.forward()
        return Episode(env, seed, goal_pos, goal_pixels, start)
    env.close()
    raise RuntimeError(
        f"No usable goal for episode seed {seed} after {task.max_goal_tries} tries (unstable or "
        f"objects moved < {task.min_goal_distance} m); lower min_goal_distance or raise goal_pushes."
    )


class Controller(Protocol):
    """Chooses the pushes of a batch of episodes (:mod:`kinet_rl.rearrangement.controllers`)."""

    def reset(self, episodes: Sequence[Episode]) -> None:
        """Called once before the first push, with the episodes it plans for."""

    def act(self, observations: Sequence[dict[str, np.ndarray]]) -> np.ndarray:
        """The next push of each episode, ``[B, 4]`` in ``[-1, 1]``, from the env observations."""


def run_episodes(
    episodes: Sequence[Episode],
    controller: Controller,
    method: str,
    task: TaskSettings,
    record: Sequence[bool] | None = None,
    observes: tuple[str, ...] | None = None,
) -> list[EpisodeResult]:
    """Runs ``task.num_steps`` pushes of ``controller`` on every episode, in lockstep.

    At each step the controller is asked once for the pushes of all episodes (one batched plan),
    then each episode's simulator takes its push. An unstable simulation ends its episode early
    (its last distance and SSIM are carried to ``T``); the controller keeps planning for it on
    its last observation, so that the others' plans and warm starts are those they would have alone.
    Episodes flagged in ``record`` keep their frames and (for KINet controllers) detected
    keypoints. With ``observes`` the controller is handed only those observation entries (e.g.
    ``("pixels",)``: no ground truth reaches a controller that plans from images).
    """
    record = [False] * len(episodes) if record is None else list(record)
    if len(record) != len(episodes):
        raise ValueError(f"record has {len(record)} flags for {len(episodes)} episodes.")
    obs = [episode.start for episode in episodes]
    distances = [
        [mean_goal_distance(o[OBJECT_POS], e.goal_pos)] for o, e in zip(obs, episodes, strict=True)
    ]
    similarities = [[goal_similarity(o, e)] for o, e in zip(obs, episodes, strict=True)]
    results = [EpisodeResult(method, e.seed, np.zeros(0), False, False) for e in episodes]
    controller.reset(episodes)
    for _ in range(task.num_steps):
        live = [i for i, result in enumerate(results) if not result.unstable]
        if not live:
            break
        seen = [o if observes is None else {key: o[key] for key in observes} for o in obs]
        actions = np.clip(np.asarray(controller.act(seen), dtype=np.float32), -1.0, 1.0)
        for i in live:
            episode = episodes[i]
            if record[i]:
                _record(results[i], controller, obs[i], i)
            obs[i] = episode.env.step(actions[i]).observation
            distances[i].append(mean_goal_distance(obs[i][OBJECT_POS], episode.goal_pos))
            similarities[i].append(goal_similarity(obs[i], episode))
            results[i].unstable = bool(episode.env.task.unstable)
    for i, (episode, result) in enumerate(zip(episodes, results, strict=True)):
        if record[i]:
            result.frames.append(obs[i][PIXELS].copy())
            result.goal_pixels = episode.goal_pixels
            goal_keypoints = _keypoints(controller, "last_goal_keypoints", i)
            if goal_keypoints is not None:
                result.goal_keypoints = goal_keypoints
        missing = task.num_steps + 1 - len(distances[i])
        result.distances = np.asarray(distances[i] + [distances[i][-1]] * missing, np.float64)
        result.goal_ssim = np.asarray(similarities[i] + [similarities[i][-1]] * missing, np.float64)
        result.success = all_within(obs[i][OBJECT_POS], episode.goal_pos, task.success_threshold)
    return results


def run_episode(
    episode: Episode,
    controller: Controller,
    method: str,
    task: TaskSettings,
    record: bool = False,
    observes: tuple[str, ...] | None = None,
) -> EpisodeResult:
    """:func:`run_episodes` for one episode."""
    return run_episodes([episode], controller, method, task, [record], observes)[0]


def _keypoints(controller: Controller, name: str, i: int) -> np.ndarray | None:
    """Episode ``i``'s keypoints ``[K, 2]`` of a KINet controller's planner, else None."""
    push_planner = getattr(controller, "push_planner", None)
    keypoints = None if push_planner is None else getattr(push_planner, name)
    return None if keypoints is None else keypoints[i].numpy()


def _record(
    result: EpisodeResult, controller: Controller, obs: dict[str, np.ndarray], i: int
) -> None:
    result.frames.append(obs[PIXELS].copy())
    keypoints = _keypoints(controller, "last_keypoints", i)
    if keypoints is not None:
        result.keypoints.append(keypoints)
