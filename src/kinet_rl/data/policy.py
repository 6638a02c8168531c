"""Random push policy whose pushes mostly touch objects, and per-episode seeding.

Every random number of an episode derives from ``(seed, episode index)``: the
:class:`EpisodeSeeding` transform seeds the env at each reset and carries the episode's seed in
the tensordict; :class:`RandomPushPolicy` seeds its generator from that seed and the step count.
So an episode's data does not depend on which worker collected it, or on how many workers ran.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.data import Composite, Unbounded
from torchrl.envs import EnvBase, Transform

from kinet_rl.config_schema import invalid, require
from kinet_rl.keys import ACTION, OBJECT_POS

EPISODE_ID = "episode_id"  # int64 [*B, 1] index of the episode within its collection run
EPISODE_SEED = "episode_seed"  # int64 [*B, 1] seed of the episode, in [0, 2**32)
STEP_COUNT = "step_count"  # int64 [*B, 1] written by torchrl's StepCounter


def episode_seed(seed: int, episode: int) -> int:
    """Returns the 32-bit seed of episode ``episode`` of a run seeded with ``seed``."""
    return int(np.random.SeedSequence([seed, episode]).generate_state(1, np.uint32)[0])


def _min_max(name: str, values: Sequence[float]) -> tuple[float, float]:
    bounds = [float(v) for v in values]
    if len(bounds) != 2 or bounds[0] > bounds[1]:
        raise invalid(name, list(values), "[min, max] with min <= max")
    return bounds[0], bounds[1]


class RandomPushPolicy(TensorDictModuleBase):
    """Samples pushes that mostly pass through an object, mixed with uniform pushes.

    With probability ``object_push_prob`` a push targets a uniformly chosen object: a direction
    is drawn uniformly, the push starts ``approach_distance`` behind the object's centre (plus a
    sideways offset of at most ``lateral_noise``) and runs ``push_length`` along the direction,
    so it passes through the object when ``push_length > approach_distance``. Otherwise start
    and end are uniform in the workspace. Every push ends inside ``[-keep_inside, keep_inside]^2``
    (object pushes redraw their direction until it does, up to 32 tries, then aim at the centre),
    so random pushes do not herd the objects to the table edges, out of the pusher's reach and
    out of the camera's view. Distances are in normalised action units (the workspace spans
    [-1, 1]); ranges are sampled uniformly; actions are clipped to [-1, 1].

    Keys:
        in: ``object_pos`` [*B, N, 2] metres, ``episode_seed`` [*B, 1], ``step_count`` [*B, 1].
        out: ``action`` [*B, 4] float32 (start x, start y, end x, end y) in [-1, 1].

    Args:
        workspace_half_size: half the side of the square workspace in metres (from the env).
        object_push_prob: probability that a push targets an object.
        approach_distance: (min, max) distance from push start to the object centre.
        push_length: (min, max) length of an object-targeting push.
        lateral_noise: largest sideways offset of the push line from the object centre.
        keep_inside: largest coordinate of a push's end point (1 disables the constraint).
    """

    def __init__(
        self,
        workspace_half_size: float,
        object_push_prob: float = 0.8,
        approach_distance: Sequence[float] = (0.15, 0.3),
        push_length: Sequence[float] = (0.3, 0.6),
        lateral_noise: float = 0.05,
        keep_inside: float = 0.8,
    ) -> None:
        super().__init__()
        require(workspace_half_size > 0, "workspace_half_size", workspace_half_size, "> 0 metres")
        require(
            0.0 <= object_push_prob <= 1.0,
            "object_push_prob",
            object_push_prob,
            "a number in [0, 1]",
        )
        self.workspace_half_size = float(workspace_half_size)
        self.object_push_prob = float(object_push_prob)
        self.approach_distance = _min_max("approach_distance", approach_distance)
        self.push_length = _min_max("push_length", push_length)
        self.lateral_noise = float(lateral_noise)
        require(0.0 < keep_inside <= 1.0, "keep_inside", keep_inside, "a number in (0, 1]")
        self.keep_inside = float(keep_inside)
        self.in_keys = [OBJECT_POS, EPISODE_SEED, STEP_COUNT]
        self.out_keys = [ACTION]

    def sample_push(self, rng: np.random.Generator, object_pos: np.ndarray) -> np.ndarray:
        """Samples one push [4] for objects at ``object_pos`` [N, 2] (normalised units)."""
        if rng.random() >= self.object_push_prob:
            start = rng.uniform(-1.0, 1.0, 2)
            return np.concatenate([start, rng.uniform(-self.keep_inside, self.keep_inside, 2)])
        target = object_pos[rng.integers(len(object_pos))]
        approach = rng.uniform(*self.approach_distance)
        offset = rng.uniform(-self.lateral_noise, self.lateral_noise)
        length = rng.uniform(*self.push_length)
        for _ in range(32):
            angle = rng.uniform(0.0, 2.0 * np.pi)
            start, end = self._object_push(target, angle, approach, offset, length)
            if np.abs(end).max() <= self.keep_inside:
                break
        else:  # aim at the workspace centre
            start, end = self._object_push(
                target, np.arctan2(-target[1], -target[0]), approach, offset, length
            )
        return np.clip(np.concatenate([start, end]), -1.0, 1.0)

    @staticmethod
    def _object_push(
        target: np.ndarray, angle: float, approach: float, offset: float, length: float
    ) -> tuple[np.ndarray, np.ndarray]:
        direction = np.array([np.cos(angle), np.sin(angle)])
        normal = np.array([-direction[1], direction[0]])
        start = target - approach * direction + offset * normal
        return start, start + length * direction

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Writes one push per batch element, seeded by (episode seed, step count)."""
        pos = tensordict.get(OBJECT_POS)  # [*B, N, 2]
        batch = pos.shape[:-2]
        flat_pos = pos.reshape(-1, *pos.shape[-2:]).double().numpy() / self.workspace_half_size
        seeds = tensordict.get(EPISODE_SEED).reshape(-1).tolist()
        steps = tensordict.get(STEP_COUNT).reshape(-1).tolist()
        actions = [
            self.sample_push(np.random.default_rng([s, t]), p)
            for s, t, p in zip(seeds, steps, flat_pos, strict=True)
        ]
        action = torch.as_tensor(np.stack(actions), dtype=torch.float32).reshape(*batch, 4)
        tensordict.set(ACTION, action)
        return tensordict


class EpisodeSeeding(Transform):
    """Seeds each episode from ``(seed, episode index)`` and writes its index and seed.

    The k-th episode of this env gets index ``first_episode + k * episode_stride``, so workers
    ``w = 0..W-1`` built with ``first_episode=start + w`` and ``episode_stride=W`` share out the
    episodes. A reset that follows a reset with no step in between reuses the index (collectors
    may reset twice before stepping); the episode replays identically because of its seed.

    Keys:
        out: ``episode_id`` [1] int64, ``episode_seed`` [1] int64 (also copied to ``next``).
    """

    def __init__(self, seed: int, first_episode: int = 0, episode_stride: int = 1) -> None:
        super().__init__(in_keys=[], out_keys=[EPISODE_ID, EPISODE_SEED])
        self.seed = int(seed)
        self.next_episode = int(first_episode)
        self.episode_stride = int(episode_stride)
        self._current: int | None = None
        self._stepped = False

    def _reset_env_preprocess(self, tensordict: TensorDictBase | None) -> TensorDictBase | None:
        if self._current is None or self._stepped:
            self._current = self.next_episode
            self.next_episode += self.episode_stride
            self._stepped = False
        base_env: EnvBase = self.parent.base_env
        base_env.set_seed(episode_seed(self.seed, self._current), static_seed=True)
        return tensordict

    def _reset(
        self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase
    ) -> TensorDictBase:
        if self._current is None:
            raise RuntimeError("EpisodeSeeding: reset reached the transform without a seed.")
        tensordict_reset.set(EPISODE_ID, torch.tensor([self._current]))
        tensordict_reset.set(EPISODE_SEED, torch.tensor([episode_seed(self.seed, self._current)]))
        return tensordict_reset

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        self._stepped = True
        next_tensordict.set(EPISODE_ID, tensordict.get(EPISODE_ID))
        next_tensordict.set(EPISODE_SEED, tensordict.get(EPISODE_SEED))
        return next_tensordict

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        for key in (EPISODE_ID, EPISODE_SEED):
            observation_spec[key] = Unbounded(
                shape=(*observation_spec.shape, 1),
                dtype=torch.int64,
                device=observation_spec.device,
            )
        return observation_spec


def read_workspace_half_size(env: EnvBase) -> float:
    """Returns the env's workspace half-size in metres (the action's [-1, 1] maps onto it).

    Looks for a ``workspace_half_size`` attribute on the env or its base env, then for the
    dm_control task's ``workspace.half_size`` behind torchrl's ``DMControlWrapper``.
    """
    base_env = getattr(env, "base_env", env)
    for candidate in (env, base_env):
        if getattr(candidate, "workspace_half_size", None) is not None:
            return float(candidate.workspace_half_size)
    task = getattr(getattr(base_env, "_env", None), "task", None)
    workspace = getattr(task, "workspace", None)
    if workspace is not None:
        return float(workspace.half_size)
    raise AttributeError(
        f"{type(env).__name__} exposes no workspace size; pass workspace_half_size= to "
        "collect_dataset, or give the env a workspace_half_size attribute."
    )
