"""Forward-prediction evaluation of world models on held-out episodes (Table I).

Every model offers ``object_rollout(geometry)``, an :class:`ObjectRollout` that predicts object
positions from the frame where a prediction starts and the logged pushes, with no ground truth from
the predicted steps (KINet reads them off its keypoints: :mod:`kinet_rl.models.object_rollout`).
Errors are in metres on the table, next to the no-motion baseline (every object stays put).
"""

from __future__ import annotations

from typing import Protocol

import torch
from tensordict import TensorDict, TensorDictBase
from torch import Tensor

from kinet_rl.devices import model_device
from kinet_rl.envs.geometry import SceneGeometry, normalised_to_pixels
from kinet_rl.evaluation.metrics import keypoint_hit_rate, position_error
from kinet_rl.keys import ACTION, OBJECT_POS, PIXELS, PIXELS_0
from kinet_rl.models.object_rollout import rollout_keypoints


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
    pos, _ = model.detector(batch[PIXELS].to(model_device(model)))
    pos = pos.cpu()
    kp_px = normalised_to_pixels(pos, geometry.image_size)
    obj_px = geometry.objects_to_pixels(batch[OBJECT_POS])
    in_view = ((obj_px >= 0) & (obj_px <= geometry.image_size - 1)).all(dim=-1)
    return keypoint_hit_rate(kp_px, obj_px, radius_px, counted=in_view)


class ObjectRollout(Protocol):
    """What forward-prediction evaluation asks of any model (KINet, baselines, user models).

    Called with a ``[B]`` TensorDict of the frame where prediction starts (``pixels``,
    ``pixels_0``, ``object_pos``: ground truth of the start frame only) and ``[B, L, 4]`` pushes;
    returns ``[B, L, N, 2]`` predicted object positions (metres, table frame) after each push.
    """

    def __call__(self, start: TensorDictBase, actions: Tensor) -> Tensor: ...


def start_frames(seq: TensorDictBase) -> TensorDictBase:
    """The ``[B]`` start-frame TensorDict of a sequence batch (see :class:`ObjectRollout`)."""
    return TensorDict(
        {
            PIXELS: seq[PIXELS][:, 0],
            PIXELS_0: seq[PIXELS_0],
            OBJECT_POS: seq[OBJECT_POS][:, 0],
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
    pred = rollout(start_frames(seq), seq[ACTION])  # [B, L, N, 2]
    truth = seq[OBJECT_POS]
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
    kp = rollout_keypoints(model, seq[PIXELS][:, 0], seq[ACTION])
    truth = seq[PIXELS].float() / 255.0
    return {
        h: (model.predict_pixels(seq[PIXELS_0], kp[:, h]) - truth[:, h]).pow(2).mean().item()
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
