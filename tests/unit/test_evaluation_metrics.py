"""Keypoint hit rate and object-position errors against ground truth."""

from __future__ import annotations

import pytest
import torch

from kinet_rl.evaluation.forward import split_errors
from kinet_rl.evaluation.metrics import keypoint_hit_rate


def test_hit_rate_counts_objects_with_a_close_keypoint():
    obj = torch.tensor([[[10.0, 10.0], [40.0, 40.0]]])
    kp = torch.tensor([[[12.0, 10.0], [60.0, 60.0], [9.0, 11.0]]])
    assert keypoint_hit_rate(kp, obj, radius_px=4.0) == 0.5
    assert keypoint_hit_rate(kp, obj, radius_px=30.0) == 1.0


def test_hit_rate_counts_only_the_selected_objects() -> None:
    kp = torch.tensor([[[10.0, 10.0]]])
    obj = torch.tensor([[[11.0, 10.0], [-30.0, 5.0]]])  # the second object is out of view
    assert keypoint_hit_rate(kp, obj, 4.0) == 0.5
    assert keypoint_hit_rate(kp, obj, 4.0, counted=torch.tensor([[True, False]])) == 1.0


def test_split_errors_leave_absent_objects_out() -> None:
    nan = float("nan")
    start = torch.tensor([[[0.0, 0.0], [1.0, 0.0]], [[0.0, 0.0], [nan, nan]]])
    truth = start + torch.tensor([[[0.1, 0.0], [0.0, 0.0]], [[0.0, 0.0], [0.0, 0.0]]])
    errors = split_errors(start, truth, start)  # no-motion errors 0.1, 0 and 0, one absent
    assert errors["all"] == pytest.approx(0.1 / 3) and errors["moved"] == pytest.approx(0.1)
    assert errors["unmoved"] == 0.0 and errors["moved_fraction"] == pytest.approx(1 / 3)
