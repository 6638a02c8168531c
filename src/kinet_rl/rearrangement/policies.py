"""The policies of the rearrangement evaluation: they choose the pushes of a batch of episodes.

A policy is a TorchRL ``TensorDictModuleBase`` that plans for ``B`` episodes at once (``B = 1``
for one at a time): one seed per episode, one batched planner call per step for all of them.
Episode ``i`` samples from its own seeded generator, so it gets the pushes it would get alone (up
to floating-point rounding of the batched arithmetic).

A planner's policy reads only what its model declares (``capabilities.observes`` and
``capabilities.goal``): KINet, Forw, ForwInv and V-CDN read camera images and the goal image, as
a real robot would; the GT-state baselines (IN, IN-full, VisIN) and the oracle read the
simulator's object state and goal positions, which is what makes them ceilings rather than peers.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from kinet_rl.keys import ACTION, GOAL_KP_POS, KP_POS
from kinet_rl.models.push_planner import PushPlanner


class RandomPolicy(TensorDictModuleBase):
    """Uniform random pushes: start and end uniform in the workspace; reads nothing."""

    def __init__(self, seeds: Sequence[int]) -> None:
        super().__init__()
        self.in_keys: list = []
        self.out_keys = [ACTION]
        self.rngs = [np.random.default_rng(seed) for seed in seeds]

    def reset(self) -> None:
        """Nothing to reset."""

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        pushes = np.stack([rng.uniform(-1.0, 1.0, 4) for rng in self.rngs])
        return tensordict.set(ACTION, torch.from_numpy(pushes.astype(np.float32)))


class PlannerPolicy(TensorDictModuleBase):
    """MPC with a model's :class:`PushPlanner`: KINet, a baseline or the oracle alike.

    Reads the observation and goal entries the model declares, writes ``action`` and, for
    keypoint models, the keypoints it detected in the image and the goal image (``KP_POS``,
    ``GOAL_KP_POS``: drawn in the episode videos).
    """

    def __init__(self, push_planner: PushPlanner) -> None:
        super().__init__()
        capabilities = push_planner.capabilities
        self.push_planner = push_planner
        self.in_keys = [*capabilities.observes, *capabilities.goal]
        self.out_keys = [ACTION, KP_POS, GOAL_KP_POS]

    def reset(self) -> None:
        """Clears the planner's warm start."""
        self.push_planner.reset()

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        observation = tensordict.select(*self.in_keys, strict=False).apply(
            lambda value: value if value.dtype == torch.uint8 else value.float()
        )
        tensordict.set(ACTION, self.push_planner.plan(observation))
        for key, value in (
            (KP_POS, self.push_planner.last_keypoints),
            (GOAL_KP_POS, self.push_planner.last_goal_keypoints),
        ):
            if value is not None:
                tensordict.set(key, value)
        return tensordict
