"""Gymnasium interface: ``kinet_rl/PushBlocks-v0`` and ``kinet_rl/PushYCB-v0``.

Registered when :mod:`kinet_rl.envs` is imported. Keyword arguments are those of
:func:`kinet_rl.envs.make_dm_env` (minus ``task``); episodes are truncated by gymnasium's
``TimeLimit`` after ``max_episode_steps`` (60 by default) pushes.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from kinet_rl.envs.factory import make_dm_env
from kinet_rl.keys import OBJECT_POS, OBJECT_SHAPE, OBJECT_YAW, PIXELS, UNSTABLE

__all__ = ["PushGymEnv", "register_gym_envs", "GYM_IDS"]

GYM_IDS = {"blocks": "kinet_rl/PushBlocks-v0", "ycb": "kinet_rl/PushYCB-v0"}


class PushGymEnv(gymnasium.Env):
    """Gymnasium view of the dm_control pushing environment.

    Observation: ``Dict(pixels uint8 [H, W, 3], object_pos float32 [N, 2], object_yaw float32 [N],
    object_shape float32 [N, 8], unstable MultiBinary(1))``; action: ``Box(-1, 1, (4,), float32)``. ``terminated`` is true when
    the simulation went unstable.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(self, task: str = "blocks", render_mode: str | None = None, **kwargs: Any) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(
                f"render_mode={render_mode!r} is not supported; use 'rgb_array' or None."
            )
        self.render_mode = render_mode
        self._env = make_dm_env(task=task, **kwargs)
        self._obs: dict[str, np.ndarray] | None = None
        task_obj = self._env.task
        size, num = task_obj.image_size, task_obj.num_objects
        self.observation_space = spaces.Dict(
            {
                PIXELS: spaces.Box(0, 255, (size, size, 3), np.uint8),
                OBJECT_POS: spaces.Box(-10.0, 10.0, (num, 2), np.float32),
                OBJECT_YAW: spaces.Box(-np.pi, np.pi, (num,), np.float32),
                OBJECT_SHAPE: spaces.Box(-1.0, 1.0, (num, 8), np.float32),
                UNSTABLE: spaces.MultiBinary(1),
            }
        )
        self.action_space = spaces.Box(-1.0, 1.0, (4,), np.float32)

    @property
    def dm_env(self):
        """The wrapped dm_control environment."""
        return self._env

    def _convert(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        obs = dict(observation)
        obs[UNSTABLE] = obs[UNSTABLE].astype(np.int8)
        obs[OBJECT_YAW] = np.clip(obs[OBJECT_YAW], -np.pi, np.pi).astype(np.float32)
        self._obs = obs
        return obs

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode; ``seed`` reseeds the task's random state."""
        super().reset(seed=seed)
        if seed is not None:
            self._env.task._random = np.random.RandomState(seed)
        return self._convert(self._env.reset().observation), {}

    def step(self, action: np.ndarray):
        """Execute one push."""
        timestep = self._env.step(action)
        obs = self._convert(timestep.observation)
        terminated = bool(obs[UNSTABLE][0])
        return (
            obs,
            float(timestep.reward or 0.0),
            terminated,
            False,
            {"unstable_count": self._env.task.unstable_count},
        )

    def render(self) -> np.ndarray | None:
        """The current camera image (``rgb_array``)."""
        if self.render_mode is None:
            return None
        if self._obs is None:
            raise RuntimeError("Call reset() before render().")
        return self._obs[PIXELS]

    def close(self) -> None:
        """Release rendering resources."""
        self._env.close()


def register_gym_envs() -> None:
    """Register the gymnasium ids (idempotent)."""
    for task, env_id in GYM_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id,
                entry_point="kinet_rl.envs.gym_env:PushGymEnv",
                max_episode_steps=60,
                kwargs={"task": task},
            )
