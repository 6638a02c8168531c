"""A metric against ground-truth objects: the keypoint hit rate (:func:`keypoint_hit_rate`).

How keypoints are related to objects is KINet's own read-out
(:mod:`kinet_rl.models.object_rollout`); these metrics only score its output.
"""

from __future__ import annotations

from torch import Tensor

from kinet_rl.models.object_rollout import pairwise_distance


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
