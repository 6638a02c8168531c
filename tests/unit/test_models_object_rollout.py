"""KINet's object read-out from keypoints: membership and predicted object positions."""

from __future__ import annotations

import torch

from kinet_rl.models.object_rollout import (
    keypoint_membership,
    pairwise_distance,
    predict_object_positions,
)


def test_pairwise_distance_shape_and_values():
    a = torch.tensor([[[0.0, 0.0], [3.0, 4.0]]])
    b = torch.tensor([[[0.0, 0.0]]])
    torch.testing.assert_close(pairwise_distance(a, b), torch.tensor([[[0.0], [5.0]]]))


def test_membership_gives_every_object_a_keypoint_and_rows_sum_to_one():
    obj = torch.tensor([[[0.0, 0.0], [1.0, 0.0], [5.0, 5.0]]])
    kp = torch.tensor([[[0.1, 0.0], [-0.1, 0.0], [0.9, 0.0], [3.0, 3.0]]])
    w = keypoint_membership(kp, obj)
    assert w.shape == (1, 3, 4)
    torch.testing.assert_close(w.sum(-1), torch.ones(1, 3))
    # object 0 owns keypoints 0 and 1 equally; object 2 owns keypoint 3 (its nearest)
    torch.testing.assert_close(w[0, 0], torch.tensor([0.5, 0.5, 0.0, 0.0]))
    torch.testing.assert_close(w[0, 2], torch.tensor([0.0, 0.0, 0.0, 1.0]))


def test_orphan_object_takes_its_nearest_keypoint():
    obj = torch.tensor([[[0.0, 0.0], [0.5, 0.0]]])
    kp = torch.tensor([[[0.0, 0.0], [0.1, 0.0]]])  # both closer to object 0
    w = keypoint_membership(kp, obj)
    torch.testing.assert_close(w[0, 1], torch.tensor([0.0, 1.0]))


def test_prediction_moves_objects_with_their_keypoints():
    obj = torch.tensor([[[0.0, 0.0], [1.0, 1.0]]])
    kp0 = torch.tensor([[[0.0, 0.0], [1.0, 1.0]]])
    kp1 = kp0 + torch.tensor([[[0.2, 0.0], [0.0, 0.0]]])
    pred = predict_object_positions(obj, kp0, kp1, keypoint_membership(kp0, obj))
    torch.testing.assert_close(pred, torch.tensor([[[0.2, 0.0], [1.0, 1.0]]]))
    mean_error = (pred - obj).norm(dim=-1).mean()  # object 0 moved 0.2, object 1 stayed
    assert abs(mean_error.item() - 0.1) < 1e-6


def test_absent_objects_take_no_keypoints():
    nan = float("nan")
    obj = torch.tensor([[[0.0, 0.0], [nan, nan], [1.0, 0.0]]])  # object 1: variable-count padding
    kp = torch.tensor([[[0.1, 0.0], [0.9, 0.0], [1.2, 0.0]]])
    w = keypoint_membership(kp, obj)
    torch.testing.assert_close(w[:, [0, 2]], keypoint_membership(kp, obj[:, [0, 2]]))
    assert predict_object_positions(obj, kp, kp + 1.0, w)[0, 1].isnan().all()
