"""KeypointTransform on a TorchRL env: specs, rollout keys and shapes, frozen detector."""

from __future__ import annotations

import pytest
import torch
from torchrl.envs import TransformedEnv
from torchrl.envs.utils import check_env_specs

from fake_push_env import make_fake_env
from kinet_rl.keys import KP_FEAT, KP_POS, PIXELS
from kinet_rl.models import KeypointDetector, KeypointTransform


def keypoint_env(**transform_kwargs) -> TransformedEnv:
    torch.manual_seed(0)
    detector = KeypointDetector(num_keypoints=3, feat_dim=4, channels=8)
    env = make_fake_env(num_objects=2, image_size=16, max_steps=3, seed=0)
    env.append_transform(KeypointTransform(detector, **transform_kwargs))
    return env


def test_specs_match_rollout():
    env = keypoint_env()
    check_env_specs(env, seed=0)
    spec = env.observation_spec
    assert spec[KP_POS].shape == (3, 2) and spec[KP_FEAT].shape == (3, 4)


def test_rollout_has_keypoints_of_each_frame():
    env = keypoint_env()
    rollout = env.rollout(3)
    assert rollout[KP_POS].shape == (3, 3, 2) and rollout[KP_FEAT].shape == (3, 3, 4)
    assert rollout[("next", *KP_POS)].shape == (3, 3, 2)
    assert rollout[KP_POS].abs().max() <= 1
    detector = env.transform[-1].detector
    with torch.no_grad():
        expected, _ = detector(rollout["next", PIXELS])
    torch.testing.assert_close(rollout[("next", *KP_POS)], expected)
    assert not rollout[KP_POS].requires_grad


def test_custom_out_keys():
    env = keypoint_env(out_keys=[("kp", "xy"), ("kp", "phi")])
    td = env.reset()
    assert td["kp", "xy"].shape == (3, 2) and td["kp", "phi"].shape == (3, 4)


def test_wrong_keys_are_named():
    detector = KeypointDetector(num_keypoints=3, feat_dim=4, channels=8)
    with pytest.raises(ValueError, match="one image in_key and two out_keys"):
        KeypointTransform(detector, out_keys=[KP_POS])
    env = make_fake_env(num_objects=2, image_size=16, seed=0)
    env.append_transform(KeypointTransform(detector, in_keys=["camera"]))
    with pytest.raises(KeyError, match="no image spec at 'camera'"):
        env.observation_spec  # noqa: B018
    with pytest.raises(KeyError, match="no image at 'camera'"):
        env.transform[-1]._call(env.base_env.reset())
