"""Object positions read off a keypoint model's keypoints (KINet, V-CDN): its forward
prediction on the table.

Keypoints carry no identity, so they are related to objects in the frame where a prediction
*starts* (never in the predicted frames): each keypoint belongs to its nearest object, and an object
that no keypoint chose takes its single nearest keypoint. An object's predicted motion is then the
mean predicted motion of its keypoints, measured on the table plane
(:class:`~kinet_rl.envs.geometry.CameraProjection`).
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torch import Tensor

from kinet_rl.devices import model_device
from kinet_rl.envs.geometry import SceneGeometry, normalised_to_pixels
from kinet_rl.keys import OBJECT_POS, PIXELS


def pairwise_distance(a: Tensor, b: Tensor) -> Tensor:
    """Euclidean distances between point sets.

    Args:
        a: [*B, K, 2] points.
        b: [*B, N, 2] points.

    Returns:
        [*B, K, N] distances.
    """
    return (a.unsqueeze(-2) - b.unsqueeze(-3)).norm(dim=-1)


def keypoint_membership(kp: Tensor, obj: Tensor) -> Tensor:
    """Soft-free assignment weights of keypoints to objects at the start frame.

    Each keypoint belongs to its nearest object; an object chosen by no keypoint takes its nearest
    keypoint as well, so every object has at least one keypoint. An object at NaN (absent: the
    padding of a variable-count dataset) takes no keypoint from the others.

    Args:
        kp: [*B, K, 2] keypoint positions (any frame in which ``obj`` is expressed).
        obj: [*B, N, 2] object positions in the same frame (NaN for absent objects).

    Returns:
        [*B, N, K] row-normalised weights: object n's motion is ``weights[n] @ keypoint_motion``.
    """
    dist = pairwise_distance(kp, obj).nan_to_num(nan=torch.inf)  # [*B, K, N]
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


def objects_from_keypoints(kp: Tensor, object_pos: Tensor, geometry: SceneGeometry) -> Tensor:
    """Object positions after each step of a keypoint trajectory (see the module docstring).

    Args:
        kp: ``[B, L + 1, K, 2]`` keypoints in ``[-1, 1]``, the first at the start frame.
        object_pos: ``[B, N, 2]`` ground-truth object positions at the start frame, metres.
        geometry: The camera geometry of the images.

    Returns:
        ``[B, L, N, 2]`` object positions after steps ``1..L``, metres.
    """
    start_px = normalised_to_pixels(kp[:, 0], geometry.image_size)
    weights = keypoint_membership(start_px, geometry.objects_to_pixels(object_pos))
    on_table = geometry.projection.to_plane(kp, geometry.object_height)
    steps = [
        predict_object_positions(object_pos, on_table[:, 0], on_table[:, h], weights)
        for h in range(1, kp.shape[1])
    ]
    return torch.stack(steps, dim=1)


class KeypointObjectRollout:
    """A keypoint model's ``ObjectRollout`` (:mod:`kinet_rl.evaluation.forward`): objects follow
    the keypoints of its ``rollout_keypoints``.

    Keypoints are related to objects in the start frame (:func:`keypoint_membership`, image
    space); each object then moves by the mean motion of its keypoints on the table plane.
    """

    def __init__(self, model, geometry: SceneGeometry) -> None:
        self.model = model
        self.geometry = geometry

    @torch.no_grad()
    def __call__(self, start: TensorDictBase, actions: Tensor) -> Tensor:
        device = model_device(self.model)
        kp = self.model.rollout_keypoints(start[PIXELS].to(device), actions.to(device)).cpu()
        return objects_from_keypoints(kp, start[OBJECT_POS], self.geometry)


class DetectorFloor:
    """The detector floor: object motion read off keypoints *detected* in the true future frames.

    The same read-out as :class:`KeypointObjectRollout` (membership in the start frame, mean
    keypoint motion on the table) applied to the detector's keypoints of the real frames instead
    of predicted ones: the error a perfect forward model of the keypoints would still make.
    """

    def __init__(self, model, geometry: SceneGeometry) -> None:
        self.model = model
        self.geometry = geometry

    @torch.no_grad()
    def __call__(self, frames: Tensor, object_pos: Tensor) -> Tensor:
        """``[B, L + 1, H, W, 3]`` frames and ``[B, N, 2]`` start positions -> ``[B, L, N, 2]``."""
        pos, _ = self.model.detector(frames.to(model_device(self.model)))
        return objects_from_keypoints(pos.cpu(), object_pos, self.geometry)
