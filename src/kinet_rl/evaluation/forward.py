"""Forward-prediction evaluation of a KINet world model on held-out episodes.

Object positions are predicted from keypoints without ground truth from the predicted steps:
keypoints are related to objects in the frame where the prediction starts
(:func:`~kinet_rl.evaluation.metrics.keypoint_membership`, in image space), the model rolls the
keypoints forward open-loop with the logged pushes, and each object moves by the mean motion of its
keypoints measured on the table plane (:class:`~kinet_rl.evaluation.projection.CameraProjection`).
Errors are in metres on the table, next to the no-motion baseline (every object stays put).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import torch
from tensordict import TensorDict, TensorDictBase
from torch import Tensor

from kinet_rl.evaluation.metrics import (
    keypoint_hit_rate,
    keypoint_membership,
    position_error,
    predict_object_positions,
)
from kinet_rl.evaluation.projection import CameraProjection, normalised_to_pixels


@dataclass(frozen=True)
class SceneGeometry:
    """How images relate to the table: the camera, the image size and the object-centre height."""

    projection: CameraProjection
    image_size: int
    object_height: float

    def objects_to_pixels(self, object_pos: Tensor) -> Tensor:
        """[*B, N, 2] metres -> [*B, N, 2] pixels."""
        uv = self.projection.objects_to_image(object_pos, self.object_height)
        return normalised_to_pixels(uv, self.image_size)


def model_device(model: torch.nn.Module) -> torch.device:
    """The device of a model's parameters (CPU for a model without any)."""
    return next(model.parameters(), torch.empty(0)).device


@torch.no_grad()
def keypoint_accuracy(
    model,
    dataset,
    geometry: SceneGeometry,
    radius_px: float = 4.0,
    num_frames: int = 512,
    seed: int = 0,
) -> float:
    """Fraction of objects in view with a detected keypoint within ``radius_px`` pixels.

    Scored on ``num_frames`` random frames; an object whose centre projects outside the image is
    not counted (no keypoint can sit on it).
    """
    generator = torch.Generator().manual_seed(seed)
    batch = dataset.sample(num_frames, generator)
    pos, _ = model.detector(batch["pixels"].to(model_device(model)))
    pos = pos.cpu()
    kp_px = normalised_to_pixels(pos, geometry.image_size)
    obj_px = geometry.objects_to_pixels(batch["object_pos"])
    in_view = ((obj_px >= 0) & (obj_px <= geometry.image_size - 1)).all(dim=-1)
    return keypoint_hit_rate(kp_px, obj_px, radius_px, counted=in_view)


@torch.no_grad()
def rollout_keypoints(model, pixels: Tensor, actions: Tensor) -> Tensor:
    """Open-loop keypoint rollout from a first frame.

    Args:
        pixels: [B, H, W, 3] frames where prediction starts.
        actions: [B, L, 4] pushes.

    Returns:
        [B, L + 1, K, 2] keypoints: detected at step 0, predicted after.
    """
    pos, feat = model.detector(pixels)
    trajectory = [pos]
    for step in range(actions.shape[1]):
        pos = model.interaction(pos, feat, actions[:, step]).next_pos
        trajectory.append(pos)
    return torch.stack(trajectory, dim=1)


class ObjectRollout(Protocol):
    """What forward-prediction evaluation asks of any model (KINet, baselines, user models).

    Called with a ``[B]`` TensorDict of the frame where prediction starts (``pixels``,
    ``pixels_0``, ``object_pos``: ground truth of the start frame only) and ``[B, L, 4]`` pushes;
    returns ``[B, L, N, 2]`` predicted object positions (metres, table frame) after each push.
    """

    def __call__(self, start: TensorDictBase, actions: Tensor) -> Tensor: ...


class KeypointObjectRollout:
    """KINet's :class:`ObjectRollout`: object motion read off the predicted keypoints.

    Keypoints are related to objects in the start frame (:func:`keypoint_membership`, image
    space); each object then moves by the mean motion of its keypoints on the table plane.
    """

    def __init__(self, model, geometry: SceneGeometry) -> None:
        self.model = model
        self.geometry = geometry

    @torch.no_grad()
    def __call__(self, start: TensorDictBase, actions: Tensor) -> Tensor:
        device = model_device(self.model)
        kp = rollout_keypoints(self.model, start["pixels"].to(device), actions.to(device)).cpu()
        object_pos = start["object_pos"]
        start_px = normalised_to_pixels(kp[:, 0], self.geometry.image_size)
        weights = keypoint_membership(start_px, self.geometry.objects_to_pixels(object_pos))
        on_table = self.geometry.projection.to_plane(kp, self.geometry.object_height)
        steps = [
            predict_object_positions(object_pos, on_table[:, 0], on_table[:, h], weights)
            for h in range(1, kp.shape[1])
        ]
        return torch.stack(steps, dim=1)


def start_frames(seq: TensorDictBase) -> TensorDictBase:
    """The ``[B]`` start-frame TensorDict of a sequence batch (see :class:`ObjectRollout`)."""
    return TensorDict(
        {
            "pixels": seq["pixels"][:, 0],
            "pixels_0": seq["pixels_0"],
            "object_pos": seq["object_pos"][:, 0],
        },
        batch_size=seq.batch_size,
    )


@torch.no_grad()
def forward_errors(
    rollout: ObjectRollout,
    dataset,
    horizons: tuple[int, ...] = (1, 5, 10),
    num_sequences: int = 256,
    seed: int = 0,
) -> dict[int, dict[str, float]]:
    """Mean object-position error (metres) after ``h`` pushes, the model against no motion.

    Returns:
        ``{h: {"model": err, "no_motion": err}}``, each averaged over objects and sequences.
    """
    generator = torch.Generator().manual_seed(seed)
    seq = dataset.sample_sequences(num_sequences, max(horizons), generator)
    pred = rollout(start_frames(seq), seq["action"])  # [B, L, N, 2]
    truth = seq["object_pos"]
    return {
        h: {
            "model": position_error(pred[:, h - 1], truth[:, h]).mean().item(),
            "no_motion": position_error(truth[:, 0], truth[:, h]).mean().item(),
        }
        for h in horizons
    }


@torch.no_grad()
def image_prediction_errors(
    model,
    dataset,
    horizons: tuple[int, ...] = (1, 5, 10),
    num_sequences: int = 256,
    seed: int = 0,
) -> dict[int, float]:
    """Mean squared error (pixels in [0, 1]) of ``f_rec(I_0, x_0, x_hat_h)`` against the true frame."""
    generator = torch.Generator().manual_seed(seed)
    seq = dataset.sample_sequences(num_sequences, max(horizons), generator).to(model_device(model))
    kp = rollout_keypoints(model, seq["pixels"][:, 0], seq["action"])
    truth = seq["pixels"].float() / 255.0
    return {
        h: (model.predict_pixels(seq["pixels_0"], kp[:, h]) - truth[:, h]).pow(2).mean().item()
        for h in horizons
    }


def forward_table(
    errors: dict[int, dict[str, float]],
    image_mse: dict[int, float] | None = None,
    name: str = "KINet",
) -> str:
    """Markdown table of :func:`forward_errors` (millimetres) and optional image errors."""
    header = f"| pushes ahead | {name} error (mm) | no-motion error (mm) | {name} / no-motion |"
    rule = "|---:|---:|---:|---:|"
    if image_mse is not None:
        header, rule = header + " image MSE |", rule + "---:|"
    lines = [header, rule]
    for h, r in sorted(errors.items()):
        row = (
            f"| {h} | {1e3 * r['model']:.1f} | {1e3 * r['no_motion']:.1f} | "
            f"{r['model'] / max(r['no_motion'], 1e-12):.2f} |"
        )
        lines.append(row + (f" {image_mse[h]:.4f} |" if image_mse is not None else ""))
    return "\n".join(lines)
