"""Forward-prediction evaluation of world models on held-out episodes (Table I).

Every model offers ``object_rollout(geometry)``, an :class:`ObjectRollout` that predicts object
positions from the frame where a prediction starts and the logged pushes, with no ground truth from
the predicted steps (KINet reads them off its keypoints: :mod:`kinet_rl.models.object_rollout`).
Errors are in metres on the table, next to the no-motion baseline (every object stays put).
Objects at NaN (the padding of a variable-count dataset, :mod:`kinet_rl.data.object_counts`)
are left out of every error.
"""

from __future__ import annotations

from typing import Protocol

import torch
from tensordict import TensorDict, TensorDictBase
from torch import Tensor

from kinet_rl.devices import model_device
from kinet_rl.envs.geometry import SceneGeometry, normalised_to_pixels
from kinet_rl.evaluation.metrics import keypoint_hit_rate
from kinet_rl.keys import ACTION, OBJECT_POS, OBJECT_SHAPE, OBJECT_YAW, PIXELS, PIXELS_0


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
    ``pixels_0``, ``object_pos`` and, where the data have them, ``object_yaw`` and
    ``object_shape``: ground truth of the start frame only) and ``[B, L, 4]`` pushes;
    returns ``[B, L, N, 2]`` predicted object positions (metres, table frame) after each push.
    """

    def __call__(self, start: TensorDictBase, actions: Tensor) -> Tensor: ...


def start_frames(seq: TensorDictBase) -> TensorDictBase:
    """The ``[B]`` start-frame TensorDict of a sequence batch (see :class:`ObjectRollout`)."""
    start = TensorDict(
        {
            PIXELS: seq[PIXELS][:, 0],
            PIXELS_0: seq[PIXELS_0],
            OBJECT_POS: seq[OBJECT_POS][:, 0],
        },
        batch_size=seq.batch_size,
    )
    yaw, shape = seq.get(OBJECT_YAW, None), seq.get(OBJECT_SHAPE, None)
    if yaw is not None:
        start[OBJECT_YAW] = yaw[:, 0]
    if shape is not None:
        start[OBJECT_SHAPE] = shape
    return start


#: An object counts as moved by a push (or pushes) when its centre moved more than this, metres.
MOVED_THRESHOLD_M = 0.005


class FloorRollout(Protocol):
    """Object positions read off the true frames (e.g. :class:`~kinet_rl.models.object_rollout.DetectorFloor`)."""

    def __call__(self, frames: Tensor, object_pos: Tensor) -> Tensor: ...


def split_errors(pred: Tensor, truth: Tensor, start: Tensor) -> dict[str, float]:
    """Mean position error (metres) over all objects, moved ones and unmoved ones.

    Args:
        pred: ``[B, N, 2]`` predicted positions.
        truth: ``[B, N, 2]`` true positions.
        start: ``[B, N, 2]`` positions where the prediction started (to tell moved objects);
            NaN for absent objects, which are not counted.
    """
    error = (pred - truth).norm(dim=-1)  # [B, N]
    present = ~start.isnan().any(dim=-1)
    motion = (truth - start).norm(dim=-1)
    moved, unmoved = motion > MOVED_THRESHOLD_M, motion <= MOVED_THRESHOLD_M
    return {
        "all": error[present].mean().item(),
        "moved": error[moved].mean().item() if moved.any() else float("nan"),
        "unmoved": error[unmoved].mean().item() if unmoved.any() else float("nan"),
        "moved_fraction": moved[present].float().mean().item(),
    }


@torch.no_grad()
def forward_errors(
    rollout: ObjectRollout,
    dataset,
    horizons: tuple[int, ...] = (1, 5, 10),
    num_sequences: int = 256,
    seed: int = 0,
    floor: FloorRollout | None = None,
) -> dict[int, dict[str, float]]:
    """Mean object-position error (metres) after ``h`` pushes: the model, no motion, the floor.

    Returns:
        ``{h: {"model": err, "no_motion": err, "model_moved": ..., "model_unmoved": ...,
        "no_motion_moved": ..., "moved_fraction": ...}}`` averaged over objects and sequences,
        plus ``"floor"``, ``"floor_moved"`` and ``"floor_unmoved"`` when ``floor`` is given
        (an object moved when it travelled more than :data:`MOVED_THRESHOLD_M`).
    """
    generator = torch.Generator().manual_seed(seed)
    seq = dataset.sample_sequences(num_sequences, max(horizons), generator)
    predictions = {"model": rollout(start_frames(seq), seq[ACTION])}  # [B, L, N, 2]
    if floor is not None:
        predictions["floor"] = floor(seq[PIXELS], seq[OBJECT_POS][:, 0])
    truth = seq[OBJECT_POS]
    out = {}
    for h in horizons:
        still = split_errors(truth[:, 0], truth[:, h], truth[:, 0])
        row = {
            "no_motion": still["all"],
            "no_motion_moved": still["moved"],
            "moved_fraction": still["moved_fraction"],
        }
        for name, pred in predictions.items():
            errors = split_errors(pred[:, h - 1], truth[:, h], truth[:, 0])
            row |= {name: errors["all"], f"{name}_moved": errors["moved"]}
            row[f"{name}_unmoved"] = errors["unmoved"]
        out[h] = row
    return out


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
    kp = model.rollout_keypoints(seq[PIXELS][:, 0], seq[ACTION])
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
    floor = all("floor" in r for r in errors.values())
    header = (
        f"| pushes ahead | {name} error (mm) | no-motion error (mm) | {name} / no-motion | "
        f"{name} on moved objects (mm) | no motion on moved (mm) | {name} on unmoved (mm) | "
        "moved objects |"
    )
    rule = "|---:|---:|---:|---:|---:|---:|---:|---:|"
    if floor:
        header, rule = header + " detector floor (mm) | floor on moved (mm) |", rule + "---:|---:|"
    if image_mse is not None:
        header, rule = header + " image MSE |", rule + "---:|"
    lines = [header, rule]
    for h, r in sorted(errors.items()):
        row = (
            f"| {h} | {1e3 * r['model']:.1f} | {1e3 * r['no_motion']:.1f} | "
            f"{r['model'] / max(r['no_motion'], 1e-12):.2f} | {1e3 * r['model_moved']:.1f} | "
            f"{1e3 * r['no_motion_moved']:.1f} | {1e3 * r['model_unmoved']:.1f} | "
            f"{100 * r['moved_fraction']:.0f}% |"
        )
        if floor:
            row += f" {1e3 * r['floor']:.1f} | {1e3 * r['floor_moved']:.1f} |"
        lines.append(row + (f" {image_mse[h]:.4f} |" if image_mse is not None else ""))
    return "\n".join(lines)
