"""Metrics that relate unsupervised keypoints to ground-truth objects.

Keypoints carry no identity, so every metric first relates keypoints to objects in the frame where
a prediction *starts* (never in the predicted frames): each keypoint belongs to its nearest object,
and an object that no keypoint chose takes its single nearest keypoint. An object's predicted
motion is then the mean predicted motion of its keypoints, measured on the table plane.
"""

from __future__ import annotations

import torch
from torch import Tensor


def pairwise_distance(a: Tensor, b: Tensor) -> Tensor:
    """Euclidean distances between point sets.

    Args:
        a: [*B, K, 2] points.
        b: [*B, N, 2] points.

    Returns:
        [*B, K, N] distances.
    """
    return (a.unsqueeze(-2) - b.unsqueeze(-3)).norm(dim=-1)


def keypoint_hit_rate(
    kp_px: Tensor, obj_px: Tensor, radius_px: float = 4.0, counted: Tensor | None = None
) -> float:
    """Fraction of objects that have at least one keypoint within ``radius_px`` pixels.

    Args:
        kp_px: [*B, K, 2] keypoints in pixels.
        obj_px: [*B, N, 2] object centres in pixels.
        radius_px: hit radius.
        counted: optional [*B, N] bool mask of the objects to count (e.g. those in view).
    """
    hits = pairwise_distance(kp_px, obj_px).amin(dim=-2) <= radius_px  # [*B, N]
    if counted is None:
        return hits.float().mean().item()
    return (hits & counted).sum().item() / max(int(counted.sum().item()), 1)


def keypoint_membership(kp: Tensor, obj: Tensor) -> Tensor:
    """Soft-free assignment weights of keypoints to objects at the start frame.

    Each keypoint belongs to its nearest object; an object chosen by no keypoint takes its nearest
    keypoint as well, so every object has at least one keypoint.

    Args:
        kp: [*B, K, 2] keypoint positions (any frame in which ``obj`` is expressed).
        obj: [*B, N, 2] object positions in the same frame.

    Returns:
        [*B, N, K] row-normalised weights: object n's motion is ``weights[n] @ keypoint_motion``.
    """
    dist = pairwise_distance(kp, obj)  # [*B, K, N]
    member = torch.nn.functional.one_hot(dist.argmin(dim=-1), obj.shape[-2]).transpose(-1, -2)
    orphan = member.sum(dim=-1, keepdim=True) == 0  # [*B, N, 1]
    nearest_kp = torch.nn.functional.one_hot(dist.argmin(dim=-2), kp.shape[-2])  # [*B, N, K]
    member = torch.where(orphan, nearest_kp, member).to(kp.dtype)
    return member / member.sum(dim=-1, keepdim=True)


def predict_object_positions(
    obj_start: Tensor, kp_start: Tensor, kp_pred: Tensor, weights: Tensor
) -> Tensor:
    """Moves each object by the mean predicted displacement of its keypoints.

    Args:
        obj_start: [*B, N, 2] ground-truth object positions where the prediction starts.
        kp_start: [*B, K, 2] keypoints at the start, on the table plane (same units as objects).
        kp_pred: [*B, K, 2] predicted keypoints on the table plane.
        weights: [*B, N, K] from :func:`keypoint_membership`.
    """
    return obj_start + weights @ (kp_pred - kp_start)


def position_error(pred: Tensor, target: Tensor) -> Tensor:
    """Mean Euclidean error per sample: [*B, N, 2] x [*B, N, 2] -> [*B]."""
    return (pred - target).norm(dim=-1).mean(dim=-1)
