"""A tiny, fast stand-in for ``kinet_rl.envs.make_env`` used by data tests (no MuJoCo).

Objects are coloured squares on a grey table; a push moves every object whose centre lies
within ``object_radius`` of the push segment to the segment's end; each object's
``object_shape`` is its square given twice. Specs match the real env.
"""

from __future__ import annotations

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Composite, Unbounded
from torchrl.envs import EnvBase, StepCounter, TransformedEnv

COLOURS = np.array([[220, 40, 40], [40, 200, 40], [40, 40, 220], [220, 200, 40], [200, 40, 200]])


class FakePushEnv(EnvBase):
    """Pushes coloured squares on a table; renders with numpy."""

    def __init__(
        self,
        num_objects: int = 3,
        image_size: int = 16,
        workspace_half_size: float = 0.3,
        object_radius: float = 0.04,
        unstable_prob: float = 0.0,
        seed: int | None = None,
    ) -> None:
        super().__init__(batch_size=torch.Size([]))
        self.num_objects = num_objects
        self.image_size = image_size
        self.workspace_half_size = workspace_half_size
        self.object_radius = object_radius
        self.unstable_prob = unstable_prob
        self._rng = np.random.default_rng(seed)
        self._pos = np.zeros((num_objects, 2))
        n, h = num_objects, image_size
        self.observation_spec = Composite(
            pixels=Bounded(0, 255, shape=(h, h, 3), dtype=torch.uint8),
            object_pos=Unbounded(shape=(n, 2), dtype=torch.float32),
            object_yaw=Unbounded(shape=(n,), dtype=torch.float32),
            object_shape=Unbounded(shape=(n, 8), dtype=torch.float32),
            unstable=Bounded(0, 1, shape=(1,), dtype=torch.bool),
        )
        self.action_spec = Bounded(-1.0, 1.0, shape=(4,), dtype=torch.float32)
        self.reward_spec = Unbounded(shape=(1,), dtype=torch.float32)

    def object_shape(self) -> torch.Tensor:
        """``[N, 8]``: each object's square, (0, 0, radius, radius) twice."""
        square = torch.tensor([0.0, 0.0, self.object_radius, self.object_radius])
        return square.repeat(self.num_objects, 2)

    def _set_seed(self, seed: int | None) -> None:
        self._rng = np.random.default_rng(seed)

    def _render(self) -> torch.Tensor:
        h = self.image_size
        img = np.full((h, h, 3), 128, dtype=np.uint8)
        pix = (self._pos / self.workspace_half_size + 1.0) * 0.5 * (h - 1)
        half = max(1, round(self.object_radius / self.workspace_half_size * 0.5 * h))
        for i, (x, y) in enumerate(np.round(pix).astype(int)):
            img[max(0, y - half) : y + half + 1, max(0, x - half) : x + half + 1] = COLOURS[i % 5]
        return torch.from_numpy(img)

    def _observation(self, unstable: bool) -> TensorDict:
        return TensorDict(
            pixels=self._render(),
            object_pos=torch.as_tensor(self._pos, dtype=torch.float32),
            object_yaw=torch.zeros(self.num_objects),
            object_shape=self.object_shape(),
            unstable=torch.tensor([unstable]),
        )

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        self._pos = self._rng.uniform(-0.6, 0.6, (self.num_objects, 2)) * self.workspace_half_size
        out = self._observation(False)
        out.update(self.full_done_spec.zero())
        return out

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict["action"].clamp(-1, 1).numpy().astype(np.float64)
        start, end = action[:2] * self.workspace_half_size, action[2:] * self.workspace_half_size
        seg = end - start
        length = np.linalg.norm(seg)
        if length > 1e-6:
            direction = seg / length
            rel = self._pos - start
            along = rel @ direction
            across = np.abs(rel @ np.array([-direction[1], direction[0]]))
            hit = (along >= 0) & (along <= length) & (across < self.object_radius)
            self._pos[hit] += np.outer(length - along[hit], direction)
        unstable = bool(self._rng.random() < self.unstable_prob)
        out = self._observation(unstable)
        out.set("reward", torch.zeros(1))
        out.set("terminated", torch.tensor([unstable]))
        out.set("done", torch.tensor([unstable]))
        return out


def make_fake_env(
    num_objects: int = 3,
    image_size: int = 16,
    max_steps: int = 6,
    unstable_prob: float = 0.0,
    seed: int | None = None,
    **ignored: object,
) -> TransformedEnv:
    """Builds the fake push env with a ``StepCounter`` that truncates at ``max_steps``."""
    base = FakePushEnv(
        num_objects=num_objects, image_size=image_size, unstable_prob=unstable_prob, seed=seed
    )
    return TransformedEnv(base, StepCounter(max_steps=max_steps))
