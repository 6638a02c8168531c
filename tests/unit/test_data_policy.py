"""Random push policy and per-episode seeding."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from fake_push_env import make_fake_env
from kinet_rl.data import EpisodeSeeding, RandomPushPolicy

HALF = 0.3


def segment_distance(point: np.ndarray, start: np.ndarray, end: np.ndarray) -> float:
    seg = end - start
    t = np.clip((point - start) @ seg / max(seg @ seg, 1e-12), 0.0, 1.0)
    return float(np.linalg.norm(start + t * seg - point))


def policy_input(batch: int, seed: int = 0) -> TensorDict:
    gen = torch.Generator().manual_seed(seed)
    return TensorDict(
        object_pos=(torch.rand(batch, 3, 2, generator=gen) - 0.5) * HALF,
        episode_seed=torch.arange(batch)[:, None],
        step_count=torch.zeros(batch, 1, dtype=torch.int64),
        batch_size=[batch],
    )


def test_object_pushes_pass_through_an_object() -> None:
    policy = RandomPushPolicy(HALF, object_push_prob=1.0, lateral_noise=0.05)
    td = policy(policy_input(200))
    pos = td["object_pos"].double().numpy() / HALF
    action = td["action"].double().numpy()
    nearest = [
        min(segment_distance(p, a[:2], a[2:]) for p in objs)
        for objs, a in zip(pos, action, strict=True)
    ]
    # Clipping at the workspace edge can shorten a push; all others pass within the noise.
    assert np.mean(np.array(nearest) <= 0.05 + 1e-6) > 0.9
    assert td["action"].shape == (200, 4) and td["action"].dtype == torch.float32


def test_mixture_moves_objects_more_often_than_uniform_pushes() -> None:
    def moved_fraction(object_push_prob: float) -> float:
        env = make_fake_env(image_size=8, max_steps=100)
        env.append_transform(EpisodeSeeding(seed=0))
        policy = RandomPushPolicy(HALF, object_push_prob=object_push_prob)
        rollout = env.rollout(100, policy)
        delta = (rollout["next", "object_pos"] - rollout["object_pos"]).abs().sum((-1, -2))
        return float((delta > 0).float().mean())

    targeted, uniform = moved_fraction(0.8), moved_fraction(0.0)
    assert targeted > 0.6 and targeted > 2 * uniform


def test_actions_depend_only_on_episode_seed_and_step() -> None:
    policy = RandomPushPolicy(HALF)
    first, again = policy(policy_input(4))["action"], policy(policy_input(4))["action"]
    later = policy(policy_input(4).set("step_count", torch.ones(4, 1, dtype=torch.int64)))
    assert torch.equal(first, again) and not torch.equal(first, later["action"])


def test_bad_policy_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="object_push_prob"):
        RandomPushPolicy(HALF, object_push_prob=1.5)
    with pytest.raises(ValueError, match="workspace_half_size"):
        RandomPushPolicy(0.0)
    with pytest.raises(ValueError, match=r"push_length: got \[0.6, 0.3\], expected \[min, max\]"):
        RandomPushPolicy(HALF, push_length=(0.6, 0.3))
    with pytest.raises(ValueError, match="approach_distance"):
        RandomPushPolicy(HALF, approach_distance=(0.1,))


def test_episode_seeding_shares_out_episodes_and_replays_them() -> None:
    env = make_fake_env(image_size=8, max_steps=3)
    env.append_transform(EpisodeSeeding(seed=5, first_episode=1, episode_stride=2))
    env.reset()  # a reset without steps keeps the episode index
    rollout = env.rollout(6, RandomPushPolicy(HALF), break_when_any_done=False)
    assert rollout["episode_id"].squeeze(-1).tolist() == [1, 1, 1, 3, 3, 3]
    alone = make_fake_env(image_size=8, max_steps=3)
    alone.append_transform(EpisodeSeeding(seed=5, first_episode=3))
    replay = alone.rollout(3, RandomPushPolicy(HALF))
    assert torch.equal(replay["pixels"], rollout["pixels"][3:])
    assert torch.equal(replay["action"], rollout["action"][3:])
