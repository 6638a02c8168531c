"""What a training run measures and shows: keypoint accuracy, forward errors, images, report.md."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torchrl.record.loggers import Logger

from kinet_rl.atomic import atomic_write_text
from kinet_rl.config_schema import at_least, require
from kinet_rl.devices import model_device
from kinet_rl.envs.geometry import SceneGeometry, normalised_to_pixels
from kinet_rl.evaluation.consistency import (
    consistency_table,
    keypoint_consistency,
    reconstruction_error,
)
from kinet_rl.evaluation.forward import (
    forward_errors,
    forward_table,
    image_prediction_errors,
    keypoint_accuracy,
)
from kinet_rl.evaluation.images import draw_keypoints, image_grid, save_png, upscale
from kinet_rl.keys import ACTION, NEXT_PIXELS, OBJECT_POS, PIXELS, PIXELS_0
from kinet_rl.training.loggers import log_media

log = logging.getLogger(__name__)

#: A detected keypoint within this many pixels of an object centre counts as a hit (at 64 px).
HIT_RADIUS_PX_AT_64 = 4.0
SUMMARY_FRAMES = 8
#: Validation sequences of the 1-push forward error logged at every validation.
VALIDATION_SEQUENCES = 128
SUMMARY_SCALE = 4


@dataclass(frozen=True)
class ReportSettings:
    """What the final evaluation of a training run measures (the ``report`` config group).

    Attributes:
        horizons: Pushes ahead at which forward prediction is scored.
        num_sequences: Test sequences per forward-prediction score.
        rearrangement_episodes: Episodes of the short rearrangement evaluation at the end of a
            KINet run (0: none).
    """

    horizons: tuple[int, ...] = (1, 5, 10)
    num_sequences: int = 256
    rearrangement_episodes: int = 2

    def __post_init__(self) -> None:
        require(
            bool(self.horizons) and min(self.horizons) >= 1,
            "horizons",
            list(self.horizons),
            "a non-empty list of integers of at least 1",
        )
        at_least(self, 1, "num_sequences")
        at_least(self, 0, "rearrangement_episodes")


def has_object_state(dataset) -> bool:
    """Whether ``dataset``'s batches carry object positions (a robot's recordings, imported,
    hold pixels and pushes only). Samples one transition with its own generator."""
    batch = dataset.sample(1, torch.Generator().manual_seed(0))
    return batch.get(OBJECT_POS, None) is not None


def hit_radius(image_size: int) -> float:
    """The keypoint hit radius in pixels, scaled from 4 px at 64 px."""
    return HIT_RADIUS_PX_AT_64 * image_size / 64


@torch.no_grad()
def summary_images(model, dataset, geometry: SceneGeometry, seed: int = 0) -> dict[str, np.ndarray]:
    """Keypoint overlays and a reconstruction grid for a few random transitions.

    Returns:
        ``{"keypoints": ..., "reconstruction": ...}`` uint8 images. The overlay row shows detected
        keypoints (coloured circles) on ``I_t``; the grid's rows are ``I_t``, its reconstruction
        ``f_rec(I_0, I_t)`` (training objective), the predicted next frame ``f_rec(I_0, x_0,
        x_hat_t+1)`` (rendered from keypoints alone) and the true next frame ``I_t+1``.
    """
    model.eval()
    batch = dataset.sample(SUMMARY_FRAMES, torch.Generator().manual_seed(seed))
    batch = batch.to(model_device(model))
    source, observed = model.detector.encode(torch.cat([batch[PIXELS_0], batch[PIXELS]])).split(
        SUMMARY_FRAMES
    )
    pos = observed.pos
    rebuilt = (model.reconstructor(source, observed) + 0.5).clamp(0.0, 1.0)
    next_pos = model.rollout_keypoints(batch[PIXELS], batch[ACTION].unsqueeze(1))[:, 1]
    predicted = model.predict_pixels(batch[PIXELS_0], next_pos)
    kp_px = normalised_to_pixels(pos, geometry.image_size)
    batch, kp_px, rebuilt, predicted = batch.cpu(), kp_px.cpu(), rebuilt.cpu(), predicted.cpu()
    overlays = [
        draw_keypoints(frame, kp, SUMMARY_SCALE)
        for frame, kp in zip(batch[PIXELS], kp_px, strict=True)
    ]
    rows = [batch[PIXELS], rebuilt, predicted, batch[NEXT_PIXELS]]
    grid = [[upscale(image, SUMMARY_SCALE) for image in row] for row in rows]
    return {"keypoints": image_grid([overlays]), "reconstruction": image_grid(grid)}


def write_summaries(
    run_dir: Path, model, dataset, geometry: SceneGeometry, tag: str
) -> dict[str, Path]:
    """Saves :func:`summary_images` as ``images/<name>_<tag>.png`` in the run directory."""
    images = summary_images(model, dataset, geometry)
    return {
        name: save_png(image, run_dir / "images" / f"{name}_{tag}.png")
        for name, image in images.items()
    }


@dataclass
class TrainingReport:
    """Periodic and final evaluation of a training run (KINet or a baseline).

    On a dataset with object state it scores forward prediction in millimetres (and keypoint
    accuracy); on one without (pixels and pushes only, e.g. a robot's recordings), what the
    images alone measure: for keypoint models the reconstruction error and the keypoint
    self-consistency in pixels (:mod:`kinet_rl.evaluation.consistency`).

    Args:
        run_dir: The run directory (images and ``report.md`` go there).
        exp_name: Experiment name, for the report's title.
        model: The world model being trained.
        val: Validation split (periodic keypoint accuracy, images).
        test: Held-out test split (final numbers).
        geometry: Image <-> table geometry of the experiment's camera.
        horizons: Pushes ahead at which forward prediction is scored.
        num_sequences: Test sequences per forward-prediction score.
        logger: The run's TorchRL logger; the image summaries go to it too (``val/<name>`` at
            each validation, ``test/<name>`` at the end), not only to ``images/``.
        held_out: Further datasets scored like the test split at the end, by name (the
            experiment's generalization sets, e.g. unseen objects or object counts).
    """

    run_dir: Path
    exp_name: str
    model: Any
    val: object
    test: object
    geometry: SceneGeometry
    horizons: tuple[int, ...] = (1, 5, 10)
    num_sequences: int = 256
    logger: Logger | None = None
    held_out: Mapping[str, object] = field(default_factory=dict)

    @property
    def has_keypoints(self) -> bool:
        """Whether the model is a keypoint model (KINet, V-CDN); other baselines get forward
        errors only."""
        return self.model.capabilities.keypoints

    @property
    def model_name(self) -> str:
        return self.model.label if self.has_keypoints else type(self.model).__name__

    def accuracy(self, dataset) -> float:
        return keypoint_accuracy(
            self.model, dataset, self.geometry, hit_radius(self.geometry.image_size)
        )

    def on_validate(self, step: int) -> dict[str, float]:
        """The 1-push forward error (mm) on validation sequences (the learning curve), and for
        keypoint models the keypoint accuracy and image summaries of the step. Without object
        state: for keypoint models the 1-push keypoint self-consistency (pixels) and the image
        summaries."""
        if not has_object_state(self.val):
            return self._validate_images(step)
        rollout = self.model.object_rollout(self.geometry)
        errors = forward_errors(rollout, self.val, (1,), VALIDATION_SEQUENCES)[1]
        scores = {"val/forward_error_1_mm": 1e3 * errors["model"]}
        scores["val/forward_error_1_moved_mm"] = 1e3 * errors["model_moved"]
        if self.has_keypoints:
            self.write_images(self.val, "val", f"step{step:06d}", step)
            scores["val/keypoint_accuracy"] = self.accuracy(self.val)
        return scores

    def _validate_images(self, step: int) -> dict[str, float]:
        """:meth:`on_validate` on a validation split without object state."""
        if not self.has_keypoints:
            return {}
        self.write_images(self.val, "val", f"step{step:06d}", step)
        one = keypoint_consistency(self.model, self.val, (1,), VALIDATION_SEQUENCES)[1]
        return {
            "val/keypoint_consistency_1_px": one["model"],
            "val/keypoint_no_motion_1_px": one["no_motion"],
        }

    def write_images(self, dataset, split: str, tag: str, step: int) -> list[Path]:
        """Writes the image summaries of ``dataset`` (:func:`write_summaries`) and logs them as
        ``<split>/<name>`` at ``step``; returns the files."""
        paths = write_summaries(self.run_dir, self.model, dataset, self.geometry, tag)
        if self.logger is not None:
            for name, path in paths.items():
                log_media(self.logger, f"{split}/{name}", path, step)
        return list(paths.values())

    def score(self, dataset) -> tuple[dict, list[str]]:
        """Forward errors (and for keypoint models keypoint accuracy and image errors) on
        ``dataset``: its numbers and its report sections (:meth:`score_images` for a dataset
        without object state)."""
        if not has_object_state(dataset):
            return self.score_images(dataset)
        rollout = self.model.object_rollout(self.geometry)
        floor = self.model.detector_floor(self.geometry) if self.has_keypoints else None
        errors = forward_errors(rollout, dataset, self.horizons, self.num_sequences, floor=floor)
        results: dict = {
            "forward_error_m": {h: e["model"] for h, e in errors.items()},
            "no_motion_error_m": {h: e["no_motion"] for h, e in errors.items()},
            "forward_errors_m": errors,
        }
        sections = []
        image_mse = None
        if self.has_keypoints:
            radius = hit_radius(self.geometry.image_size)
            accuracy = self.accuracy(dataset)
            image_mse = image_prediction_errors(
                self.model, dataset, self.horizons, self.num_sequences
            )
            results.update(keypoint_accuracy=accuracy, hit_radius_px=radius, image_mse=image_mse)
            sections.append(
                f"**Keypoint accuracy: {100 * accuracy:.1f}%** of the objects in view have a "
                f"detected keypoint within {radius:.1f} px of their centre.\n"
            )
        sections.append(
            "Forward prediction: open-loop rollouts of the logged pushes, errors in millimetres "
            "on the table (protocol: docs/kinet.md).\n"
        )
        sections.append(forward_table(errors, image_mse, self.model_name) + "\n")
        return results, sections

    def score_images(self, dataset) -> tuple[dict, list[str]]:
        """What ``dataset``'s images alone measure, for a dataset without object state: for
        keypoint models the reconstruction error, the keypoint self-consistency after each
        horizon's pushes beside no motion (pixels) and the predicted frames' image errors; its
        numbers and its report sections."""
        results: dict = {"object_state": False}
        sections = [
            "No object state in these episodes (pixels and pushes only): forward errors in "
            "millimetres need object positions, so what follows is measured on the images.\n"
        ]
        if not self.has_keypoints:
            sections.append(
                f"{self.model_name} has no keypoints and no decoder to score against the "
                "images; its validation losses (the run's logs) are its measure here.\n"
            )
            return results, sections
        size = self.geometry.image_size
        rec = reconstruction_error(self.model, dataset, self.num_sequences)
        consistency = keypoint_consistency(self.model, dataset, self.horizons, self.num_sequences)
        image_mse = image_prediction_errors(self.model, dataset, self.horizons, self.num_sequences)
        results.update(
            reconstruction_mse=rec, keypoint_consistency_px=consistency, image_mse=image_mse
        )
        sections += [
            f"**Reconstruction error: {rec:.4f}** (mean squared error of rebuilding a frame from "
            "the episode's first frame and the frame's own keypoints, pixel values in [0, 1]).\n",
            "Keypoint self-consistency: open-loop rollouts of the logged pushes; the keypoints "
            "predicted after each number of pushes against those the detector finds in the true "
            f"frame then, mean distance in pixels of the {size} px images; no motion: the "
            "keypoints detected at the start, left where they are. Image MSE: the frame rendered "
            "from the predicted keypoints against the true frame.\n",
            consistency_table(consistency, image_mse, self.model_name) + "\n",
        ]
        return results, sections

    def final(self, step: int) -> dict:
        """Evaluates on the test split and every held-out set, writes ``report.md`` and final
        images; returns the numbers (a held-out set's under ``held_out/<name>``)."""
        self.model.eval()
        scores, sections = self.score(self.test)
        results: dict = {"step": step, "model": self.model_name, **scores}
        sections = [
            f"# {self.exp_name}: {self.model_name} after {step} steps\n",
            "## Held-out test episodes\n",
            *sections,
        ]
        if self.has_keypoints:
            paths = self.write_images(self.test, "test", "final", step)
            sections.append("\n".join(f"![{p.stem}](images/{p.name})" for p in paths) + "\n")
        if self.held_out:
            results["held_out"] = {}
        for name, dataset in self.held_out.items():
            results["held_out"][name], extra = self.score(dataset)
            sections += [
                f"## Held-out set `{name}` (every episode, none seen in training)\n",
                *extra,
            ]
        atomic_write_text(self.run_dir / "report.md", "\n".join(sections))
        log.info("Wrote %s", self.run_dir / "report.md")
        return results
