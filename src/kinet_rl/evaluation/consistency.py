"""What a keypoint model's training shows without object state: reconstruction error and keypoint
self-consistency (:func:`keypoint_consistency`), measured on the images alone.

A dataset of pixels and pushes only (a robot's recordings, imported) has no object positions to
score predictions in millimetres against (:mod:`kinet_rl.evaluation.forward`). What remains is
whether the model agrees with itself: the keypoints it predicts after ``h`` logged pushes against
the keypoints its detector finds in the true frame ``h`` pushes later, in pixels, next to no
motion (the keypoints detected at the start, left where they are); and how well the keypoints
rebuild the frames they were detected in (the training objective ``loss_rec``).
"""

from __future__ import annotations

import torch

from kinet_rl.devices import model_device
from kinet_rl.keys import ACTION, PIXELS, PIXELS_0
from kinet_rl.models.keypoints import pixels_to_input


@torch.no_grad()
def keypoint_consistency(
    model,
    dataset,
    horizons: tuple[int, ...] = (1, 5, 10),
    num_sequences: int = 256,
    seed: int = 0,
) -> dict[int, dict[str, float]]:
    """Mean distance (pixels) between predicted and detected keypoints after ``h`` pushes.

    Args:
        model: A keypoint model (``capabilities.keypoints``: KINet, V-CDN) with ``detector``
            and ``rollout_keypoints``.
        dataset: Sequences to score (``sample_sequences``); needs no object state.
        horizons: Pushes ahead.
        num_sequences: Sequences sampled (seeded by ``seed``).

    Returns:
        ``{h: {"model": px, "no_motion": px}}``: the mean over sequences and keypoints of the
        distance between keypoint ``k`` of the open-loop rollout after ``h`` pushes and keypoint
        ``k`` detected in the true frame ``h`` (``"model"``), and between keypoint ``k`` detected
        at the start and in frame ``h`` (``"no_motion"``), in pixels of the model's images.
    """
    generator = torch.Generator().manual_seed(seed)
    seq = dataset.sample_sequences(num_sequences, max(horizons), generator)
    seq = seq.to(model_device(model))
    frames = seq[PIXELS]  # [B, L+1, H, W, 3]
    batch, steps, size = frames.shape[0], frames.shape[1], frames.shape[2]
    predicted = model.rollout_keypoints(frames[:, 0], seq[ACTION])  # [B, L+1, K, 2]
    detected, _ = model.detector(frames.flatten(0, 1))
    detected = detected.view(batch, steps, *detected.shape[1:])  # [B, L+1, K, 2]
    px = size / 2.0  # normalised [-1, 1] image coordinates -> pixels

    def distance(a: torch.Tensor, b: torch.Tensor) -> float:
        return (px * (a - b).norm(dim=-1)).mean().item()

    return {
        h: {
            "model": distance(predicted[:, h], detected[:, h]),
            "no_motion": distance(detected[:, 0], detected[:, h]),
        }
        for h in horizons
    }


@torch.no_grad()
def reconstruction_error(model, dataset, num_frames: int = 256, seed: int = 0) -> float:
    """Mean squared error (pixel values in ``[0, 1]``) of ``f_rec(I_0, I_t)`` against ``I_t``.

    The keypoint models' ``loss_rec`` (detector and reconstructor rebuild a frame from the
    episode's first frame and the frame's own keypoints), on ``num_frames`` random frames.
    """
    batch = dataset.sample(num_frames, torch.Generator().manual_seed(seed))
    batch = batch.to(model_device(model))
    source = model.detector.encode(batch[PIXELS_0])
    observed = model.detector.encode(batch[PIXELS])
    target = pixels_to_input(batch[PIXELS]).permute(0, 2, 3, 1)
    return (model.reconstructor(source, observed) - target).pow(2).mean().item()


def consistency_table(
    consistency: dict[int, dict[str, float]],
    image_mse: dict[int, float] | None = None,
    name: str = "KINet",
) -> str:
    """Markdown table of :func:`keypoint_consistency` (pixels) and optional image errors."""
    header = f"| pushes ahead | {name} (px) | no motion (px) | {name} / no motion |"
    rule = "|---:|---:|---:|---:|"
    if image_mse is not None:
        header, rule = header + " image MSE |", rule + "---:|"
    lines = [header, rule]
    for h, row in sorted(consistency.items()):
        ratio = row["model"] / max(row["no_motion"], 1e-12)
        line = f"| {h} | {row['model']:.2f} | {row['no_motion']:.2f} | {ratio:.2f} |"
        lines.append(line + (f" {image_mse[h]:.4f} |" if image_mse is not None else ""))
    return "\n".join(lines)
