"""The rearrangement task: episodes with reachable goals, and running a policy on them.

How an episode is made (seeded by its ``seed`` alone):

1. ``make_dm_env(..., seed=seed)`` is reset: objects are placed at random, collision-free
   poses in the workspace (the environment's own initial-state distribution).
2. From that start, ``goal_pushes`` object-directed random pushes (the data-collection
   :class:`~kinet_rl.data.policy.RandomPushPolicy` with every push aimed at an object) are
   simulated; the resulting object positions and camera image are the goal. The goal is thus
   reachable by construction in ``goal_pushes`` pushes, well within ``T``.
3. A draw is rejected and redrawn (new placement) when the simulation goes unstable or the
   objects moved on average less than ``min_goal_distance`` metres.
4. The physics state of step 1 is restored and the policy gets ``num_steps`` pushes: a TorchRL
   rollout of :class:`EpisodesEnv` (the episodes as one batched env, goals in the tensordict).

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
import torch
from tensordict import NestedKey, TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.data import Bounded, Composite, Unbounded
from torchrl.envs import EnvBase

from kinet_rl.data.policy import RandomPushPolicy
from kinet_rl.envs import make_dm_env
from kinet_rl.envs.settings import SceneSettings
from kinet_rl.envs.workspace import workspace_for
from kinet_rl.evaluation.similarity import ssim
from kinet_rl.keys import (
    ACTION,
    GOAL_DISTANCE,
    GOAL_KP_POS,
    GOAL_OBJECT_POS,
    GOAL_PIXELS,
    GOAL_SSIM,
    KP_POS,
    OBJECT_POS,
    PIXELS,
)
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
    env = make_dm_env(**scene.as_dict(), seed=seed)
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


class Policy(Protocol):
    """Chooses the pushes of a batch of episodes: a TorchRL policy (``TensorDictModuleBase``)
    that reads its ``in_keys`` (the observation entries and goal entries it declares) and writes
    ``action`` ``[B, 4]`` in ``[-1, 1]`` (:mod:`kinet_rl.rearrangement.policies`)."""

    in_keys: list[NestedKey]

    def reset(self) -> None:
        """Called once before the first push."""

    def __call__(self, tensordict: TensorDictBase) -> TensorDictBase: ...


class EpisodesEnv(EnvBase):
    """``B`` live episodes as one TorchRL env of batch ``[B]``, the goal in the tensordict.

    Reset returns each episode's start observation (the env is not reset: the episode is at its
    start state) with its goal (``("goal", "pixels")``, ``("goal", "object_pos")``); a step pushes
    each episode that is still stable (an unstable simulation has ended its episode: it keeps its
    last observation, so its distance and SSIM are carried to ``T``). Every observation carries
    the ground-truth ``goal_distance`` (metres) and the ``goal_ssim`` of the image to the goal
    image, computed from the simulator's own arrays; the reward is minus the goal distance.
    Episodes never report ``done``: an episode lasts ``T`` pushes.
    """

    def __init__(self, episodes: Sequence[Episode]) -> None:
        super().__init__(batch_size=torch.Size([len(episodes)]))
        self.episodes = list(episodes)
        batch = self.batch_size
        start = episodes[0].start
        specs = {
            key: Unbounded((*batch, *value.shape), dtype=torch.from_numpy(value).dtype)
            for key, value in start.items()
        }
        specs[GOAL_PIXELS] = specs[PIXELS].clone()
        specs[GOAL_OBJECT_POS] = specs[OBJECT_POS].clone()
        specs[GOAL_DISTANCE] = Unbounded(batch, dtype=torch.float64)
        specs[GOAL_SSIM] = Unbounded(batch, dtype=torch.float64)
        self.observation_spec = Composite(specs, shape=batch)
        self.action_spec = Bounded(-1.0, 1.0, (*batch, 4))
        self.reward_spec = Unbounded((*batch, 1), dtype=torch.float64)
        self.observations: list[dict[str, np.ndarray]] = []

    def _observe(self) -> TensorDictBase:
        observations, episodes = self.observations, self.episodes
        keys = observations[0].keys()
        entries = {key: np.stack([obs[key] for obs in observations]) for key in keys}
        entries[GOAL_PIXELS] = np.stack([e.goal_pixels for e in episodes])
        entries[GOAL_OBJECT_POS] = np.stack([e.goal_pos for e in episodes])
        distance = [mean_goal_distance(o[OBJECT_POS], e.goal_pos) for o, e in self._pairs()]
        entries[GOAL_DISTANCE] = np.asarray(distance, np.float64)
        entries[GOAL_SSIM] = np.asarray([goal_similarity(o, e) for o, e in self._pairs()])
        out = TensorDict(
            {key: torch.from_numpy(value) for key, value in entries.items()}, self.batch_size
        )
        out.set("reward", -out.get(GOAL_DISTANCE).unsqueeze(-1))
        return out

    def _pairs(self) -> list[tuple[dict[str, np.ndarray], Episode]]:
        return list(zip(self.observations, self.episodes, strict=True))

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        self.observations = [dict(episode.start) for episode in self.episodes]
        return self._observe().exclude("reward")

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        actions = np.clip(tensordict.get(ACTION).numpy().astype(np.float32), -1.0, 1.0)
        for i, episode in enumerate(self.episodes):
            if not episode.env.task.unstable:
                self.observations[i] = episode.env.step(actions[i]).observation
        return self._observe()

    def _set_seed(self, seed: int | None) -> None:
        """The episodes are seeded when made (:func:`make_episode`)."""


def run_episodes(
    episodes: Sequence[Episode],
    policy: Policy,
    method: str,
    task: TaskSettings,
    record: Sequence[bool] | None = None,
) -> list[EpisodeResult]:
    """Runs ``task.num_steps`` pushes of ``policy`` on every episode: one TorchRL rollout of an
    :class:`EpisodesEnv`, one batched plan per step for all episodes.

    The policy is handed only the entries it declares (``policy.in_keys``): no ground truth
    reaches a policy that plans from images. An unstable simulation ends its episode early (its
    last distance and SSIM are carried to ``T``); the policy keeps planning for it on its last
    observation, so that the others' plans and warm starts are those they would have alone.
    Episodes flagged in ``record`` keep their frames and (for keypoint models) the detected
    keypoints.
    """
    record = [False] * len(episodes) if record is None else list(record)
    if len(record) != len(episodes):
        raise ValueError(f"record has {len(record)} flags for {len(episodes)} episodes.")
    env = EpisodesEnv(episodes)
    policy.reset()
    rollout = env.rollout(
        task.num_steps, DeclaredInputs(policy), auto_reset=True, break_when_any_done=False
    )
    results = []
    for i, episode in enumerate(episodes):
        steps = rollout[i]
        final = steps[-1].get("next")
        result = EpisodeResult(
            method,
            episode.seed,
            torch.cat([steps[:1].get(GOAL_DISTANCE), steps.get(("next", GOAL_DISTANCE))]).numpy(),
            all_within(final.get(OBJECT_POS).numpy(), episode.goal_pos, task.success_threshold),
            bool(episode.env.task.unstable),
            torch.cat([steps[:1].get(GOAL_SSIM), steps.get(("next", GOAL_SSIM))]).numpy(),
        )
        if record[i]:
            _record(result, steps, episode)
        results.append(result)
    return results


class DeclaredInputs(TensorDictModuleBase):
    """Runs ``policy`` on the entries it declares only and returns its outputs."""

    def __init__(self, policy: Policy) -> None:
        super().__init__()
        self.policy = policy
        self.in_keys = list(policy.in_keys)
        self.out_keys = [ACTION, KP_POS, GOAL_KP_POS]

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        outputs = self.policy(tensordict.select(*self.in_keys))
        return tensordict.update(outputs.exclude(*self.in_keys))


def _record(result: EpisodeResult, steps: TensorDictBase, episode: Episode) -> None:
    """Frames (and planned keypoints) of the pushes the episode took while stable, and its end."""
    live = ~steps.get("unstable").squeeze(-1)
    result.frames = [frame.numpy() for frame in steps.get(PIXELS)[live]]
    result.frames.append(steps[-1].get(("next", PIXELS)).numpy())
    result.goal_pixels = episode.goal_pixels
    if KP_POS in steps.keys(True):
        result.keypoints = [keypoints.numpy() for keypoints in steps.get(KP_POS)[live]]
        result.goal_keypoints = steps[-1].get(GOAL_KP_POS).numpy()


def run_episode(
    episode: Episode,
    policy: Policy,
    method: str,
    task: TaskSettings,
    record: bool = False,
) -> EpisodeResult:
    """Runs one episode (see :func:`run_episodes`)."""
    return run_episodes([episode], policy, method, task, [record])[0]
