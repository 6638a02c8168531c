"""Rearrangement episodes a test plans: final distances to the goal of a policy, in mm."""

from __future__ import annotations

import numpy as np

from kinet_rl.envs import SceneSettings
from kinet_rl.rearrangement.episodes import make_episode, run_episodes
from kinet_rl.rearrangement.settings import SPLIT_SEEDS, TaskSettings


def validation_seeds(episodes: int) -> tuple[int, ...]:
    """The first ``episodes`` validation episodes' seeds."""
    return tuple(SPLIT_SEEDS["validation"] + i for i in range(episodes))


def final_distances_mm(
    policy, scene: SceneSettings, task: TaskSettings, episodes: int
) -> np.ndarray:
    """Mean object distance to the goal after ``task.num_steps`` pushes of ``policy``, mm, on
    each of the first ``episodes`` validation episodes of ``scene``."""
    started = [make_episode(scene, task, seed) for seed in validation_seeds(episodes)]
    try:
        results = run_episodes(started, policy, "planner", task)
    finally:
        for episode in started:
            episode.close()
    return np.array([1e3 * r.distances[-1] for r in results])
