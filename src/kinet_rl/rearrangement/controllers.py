"""Controllers of the rearrangement evaluation: they choose the pushes of a batch of episodes.

A controller plans for ``B`` episodes at once (``B = 1`` for one at a time): one seed per
episode, one observation per episode at each step, one batched planner call for all of them.
Episode ``i`` samples from its own seeded generator, so it gets the pushes it would get alone (up
to floating-point rounding of the batched arithmetic).

A planner's controller sees only what its model declares (``capabilities.observes``): KINet,
Forw, ForwInv and V-CDN see camera images, as a real robot would; the GT-state baselines (IN,
IN-full, VisIN) and the oracle see the simulator's object state, which is what makes them
ceilings rather than peers.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import torch
from tensordict import TensorDict
from torch import Tensor

from kinet_rl.keys import GOAL_OBJECT_POS, GOAL_PIXELS, PIXELS
from kinet_rl.models.push_planner import PushPlanner
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


class PlannerController:
    """MPC with a model's :class:`PushPlanner`: KINet, a baseline or the oracle alike.

    Each step it stacks the observation entries the model declares
    (``capabilities.observes``) and the episodes' goals (``capabilities.goal``: goal images, or
    goal object positions for the ground-truth models) into one tensordict and plans.
    """

    def __init__(self, push_planner: PushPlanner) -> None:
        self.push_planner = push_planner
        self.goal: TensorDict | None = None

    def reset(self, episodes: Sequence[Episode]) -> None:
        """Sets the goals and clears the warm start."""
        goals = {
            GOAL_PIXELS: lambda: torch.from_numpy(np.stack([e.goal_pixels for e in episodes])),
            GOAL_OBJECT_POS: lambda: torch.as_tensor(
                np.stack([e.goal_pos for e in episodes]), dtype=torch.float32
            ),
        }
        keys = self.push_planner.capabilities.goal
        self.goal = TensorDict({key: goals[key]() for key in keys}, batch_size=[len(episodes)])
        self.push_planner.reset()

    def act(self, observations: Observations) -> np.ndarray:
        """Plans from the current observations."""
        if self.goal is None:
            raise RuntimeError(
                "PlannerController.act called before reset(episodes); reset it first."
            )
        observation = self.goal.clone(False)
        for key in self.push_planner.capabilities.observes:
            observation.set(
                key, stacked(observations, key, None if key == PIXELS else torch.float32)
            )
        return self.push_planner.plan(observation).numpy()
