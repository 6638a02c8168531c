"""Training losses of the baselines, as TorchRL ``LossModule``s returning weighted ``loss_*``.

Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 4 (Baselines).
"""

from __future__ import annotations

import torch
import torch.distributed as dist
import torch.nn.functional as F
from tensordict import TensorDict, TensorDictBase
from torch import Tensor
from torchrl.objectives import LossModule

from kinet_rl.baselines.image_models import ImageForwardModel
from kinet_rl.baselines.object_models import ObjectInteractionModel
from kinet_rl.baselines.vcdn import VCDNWorldModel
from kinet_rl.keys import (
    ACTION,
    FUTURE_ACTION,
    FUTURE_PIXELS,
    NEXT_OBJECT_POS,
    NEXT_PIXELS,
    OBJECT_POS,
    PIXELS,
    PIXELS_0,
)
from kinet_rl.models.losses import check_loss_weights, keypoint_error


def _require(tensordict: TensorDictBase, keys: list, what: str) -> list[Tensor]:
    """The entries ``keys`` of a batch, or a KeyError naming every key ``what`` needs."""
    missing = [key for key in keys if tensordict.get(key, None) is None]
    if missing:
        raise KeyError(f"A {what} training batch needs {keys}; missing: {missing}.")
    return [tensordict.get(key) for key in keys]


def feature_info_nce(predicted: Tensor, target: Tensor, temperature: float = 1.0) -> Tensor:
    """InfoNCE with logits ``-|z_hat_b - z'_c|^2 / temperature``; sample ``b``'s positive is ``c = b``.

    Args:
        predicted: ``[B, D]`` predicted next features.
        target: ``[B, D]`` features of the true next frames (the other rows are negatives).
    """
    logits = -torch.cdist(predicted, target).pow(2) / temperature
    return F.cross_entropy(logits, torch.arange(predicted.shape[0], device=predicted.device))


class ImageForwardLoss(LossModule):
    """Losses of Forw (``inv_weight = 0``) and ForwInv.

    ``loss_fwd``: mean over the batch of ``|z_hat_t+1 - z_t+1|^2`` (gradient to both sides).
    ``loss_ctr``: :func:`feature_info_nce` between predicted and true next features, which stops
    the features from collapsing (other samples' next frames are the negatives). ``loss_inv``
    (ForwInv only): ``|f_inv(z_t, z_t+1) - u_t|^2``. ``loss_probe``: the evaluation probe's
    squared error on ground-truth displacements (workspace units) from *detached* features; it
    trains only the probe, and only on batches with object positions (a robot's recordings
    without object state train the rest). Each entry is already weighted.

    Keys:
        Reads a ``[B]`` batch with ``PIXELS``, ``("next", PIXELS)`` ``[B, H, W, 3]``, ``ACTION``
        ``[B, 4]`` and, where the data have them, ``OBJECT_POS`` and ``("next", OBJECT_POS)``
        ``[B, N, 2]`` (probe only). Returns scalars ``loss_fwd``, ``loss_ctr``, ``loss_probe``
        (with object positions) and, for ForwInv, ``loss_inv``.

    Args:
        world_model: An :class:`ImageForwardModel` (or :class:`ImageForwardInverseModel`).
        fwd_weight: Weight of ``loss_fwd``.
        ctr_weight: Weight of ``loss_ctr``.
        inv_weight: Weight of ``loss_inv``; must be 0 unless the model has an inverse model.
        probe_weight: Weight of ``loss_probe``.
        ctr_temperature: Temperature of the contrastive logits.
    """

    def __init__(
        self,
        world_model: ImageForwardModel,
        fwd_weight: float = 1.0,
        ctr_weight: float = 1.0,
        inv_weight: float = 0.0,
        probe_weight: float = 1.0,
        ctr_temperature: float = 1.0,
    ) -> None:
        super().__init__()
        check_loss_weights(
            ctr_temperature,
            fwd_weight=fwd_weight,
            ctr_weight=ctr_weight,
            inv_weight=inv_weight,
            probe_weight=probe_weight,
        )
        if inv_weight > 0 and not world_model.has_inverse_model:
            raise ValueError(
                f"inv_weight={inv_weight} needs an inverse model, but the model is a "
                f"{type(world_model).__name__}; use model=forwinv (ImageForwardInverseModel) or "
                "set loss.inv_weight=0."
            )
        self.world_model = world_model
        self.fwd_weight = fwd_weight
        self.ctr_weight = ctr_weight
        self.inv_weight = inv_weight
        self.probe_weight = probe_weight
        self.ctr_temperature = ctr_temperature

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        """Computes the weighted losses (see class docstring)."""
        pixels, next_pixels, action = _require(
            tensordict, [PIXELS, NEXT_PIXELS, ACTION], type(self.world_model).__name__
        )
        model = self.world_model
        feat, next_feat = model.encode(torch.cat([pixels, next_pixels])).chunk(2)
        predicted = model.predict(feat, action)
        losses = {
            "loss_fwd": self.fwd_weight * (predicted - next_feat).pow(2).sum(-1).mean(),
            "loss_ctr": self.ctr_weight
            * feature_info_nce(predicted, next_feat, self.ctr_temperature),
        }
        if model.has_inverse_model:
            inferred = model.infer_action(feat, next_feat)
            losses["loss_inv"] = self.inv_weight * (inferred - action).pow(2).sum(-1).mean()
        if tensordict.get(OBJECT_POS, None) is None:  # no object state: nothing to probe
            return TensorDict(losses, batch_size=[])
        pos, next_pos = _require(
            tensordict, [OBJECT_POS, NEXT_OBJECT_POS], f"{type(model).__name__} probe"
        )
        scale = model.position_scale
        motion = model.probe(feat.detach(), next_feat.detach(), pos / scale)
        probe_error = (motion - (next_pos - pos) / scale).pow(2).sum(-1).mean()
        losses["loss_probe"] = self.probe_weight * probe_error
        return TensorDict(losses, batch_size=[])


class ObjectForwardLoss(LossModule):
    """Loss of IN, IN-full and VisIN: squared error of the predicted next object positions.

    ``loss_fwd``: mean over the batch of ``sum_n |p_hat_n - p_n|^2`` in workspace units
    (``xy / half_size``), weighted by ``fwd_weight``.

    Keys:
        Reads a ``[B]`` batch with ``OBJECT_POS``, ``("next", OBJECT_POS)`` ``[B, N, 2]``,
        ``ACTION`` ``[B, 4]`` and, for VisIN, ``PIXELS`` ``[B, H, W, 3]``, for IN-full
        ``OBJECT_YAW`` ``[B, N]`` and ``OBJECT_SHAPE`` ``[B, N, 8]``. Returns ``loss_fwd``.

    Args:
        world_model: An :class:`ObjectInteractionModel` (IN), ``FullStateInteractionModel`` or
            ``VisualInteractionModel``.
        fwd_weight: Weight of ``loss_fwd``.
    """

    def __init__(self, world_model: ObjectInteractionModel, fwd_weight: float = 1.0) -> None:
        super().__init__()
        check_loss_weights(fwd_weight=fwd_weight)
        self.world_model = world_model
        self.fwd_weight = fwd_weight

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        """Computes the weighted loss (see class docstring)."""
        pos, next_pos, action = _require(
            tensordict, [OBJECT_POS, NEXT_OBJECT_POS, ACTION], type(self.world_model).__name__
        )
        model = self.world_model
        predicted = model.predict(pos, model.node_features(tensordict), action)
        error = ((predicted - next_pos) / model.position_scale).pow(2).sum(dim=(-2, -1)).mean()
        return TensorDict({"loss_fwd": self.fwd_weight * error}, batch_size=[])


class VCDNLoss(LossModule):
    """Losses of V-CDN, in two stages over the run's ``total_steps`` optimiser steps.

    Perception stage, the first ``round(perception_fraction * total_steps)`` training calls:
    ``loss_rec``, the error of rebuilding ``I_t`` from ``I_0`` through the keypoints (KINet's
    ``loss_rec``); only detector and reconstructor learn. Dynamics stage, the rest: the detector
    is frozen (keypoints are detected without gradient) and inference and dynamics learn from
    ``loss_fwd``, the mean over the batch of ``sum_k |x_hat_t+1 - x_t+1|^2`` against the detected
    next keypoints, ``loss_kl``, the edge-type posterior's KL to the uniform prior, and (with
    ``rollout_weight > 0``) ``loss_rollout``, the same error over an open-loop rollout of the
    pushes after each transition on the graph inferred at ``x_t``. Each entry is already weighted.

    The stage is counted by the buffer ``step`` (calls in training mode); it is saved with the
    loss's state, so a resumed run continues where it stopped. Data-parallel training is refused:
    the stages train different parameters, which DistributedDataParallel's static graph forbids.

    Keys:
        Reads a ``[B]`` batch with ``PIXELS_0`` and ``PIXELS`` (perception), ``PIXELS``,
        ``("next", PIXELS)`` ``[B, H, W, 3]`` and ``ACTION`` ``[B, 4]`` (dynamics) and, for the
        rollout, ``FUTURE_PIXELS`` ``[B, H - 1, ...]`` and ``FUTURE_ACTION``. Returns
        ``loss_rec`` (perception) or ``loss_fwd``, ``loss_kl`` and ``loss_rollout`` (dynamics).

    Reference: Li et al., NeurIPS 2020 (perception trained first, then inference and dynamics).

    Args:
        world_model: The :class:`VCDNWorldModel` being trained.
        total_steps: Optimiser steps of the run (``trainer.steps``).
        perception_fraction: Share of ``total_steps`` that trains perception.
        rec_weight: Weight of ``loss_rec``.
        fwd_weight: Weight of ``loss_fwd``.
        kl_weight: Weight of ``loss_kl``.
        rollout_weight: Weight of ``loss_rollout`` (0: off; needs ``trainer.horizon > 1``).
    """

    step: Tensor

    def __init__(
        self,
        world_model: VCDNWorldModel,
        total_steps: int,
        perception_fraction: float = 0.5,
        rec_weight: float = 1.0,
        fwd_weight: float = 1.0,
        kl_weight: float = 0.01,
        rollout_weight: float = 0.0,
    ) -> None:
        super().__init__()
        check_loss_weights(
            rec_weight=rec_weight,
            fwd_weight=fwd_weight,
            kl_weight=kl_weight,
            rollout_weight=rollout_weight,
        )
        self.perception_steps = round(perception_fraction * total_steps)
        if not 0 < self.perception_steps < total_steps:
            raise ValueError(
                f"perception_fraction={perception_fraction} of total_steps={total_steps} gives "
                f"{self.perception_steps} perception steps; both stages need at least one step: "
                "choose a fraction in (0, 1) and trainer.steps >= 2."
            )
        if dist.is_available() and dist.is_initialized() and dist.get_world_size() > 1:
            raise ValueError(
                "V-CDN trains perception and dynamics in separate stages, which data-parallel "
                "training does not support; train it in one process (no torchrun)."
            )
        self.world_model = world_model
        self.rec_weight = rec_weight
        self.fwd_weight = fwd_weight
        self.kl_weight = kl_weight
        self.rollout_weight = rollout_weight
        self.register_buffer("step", torch.zeros((), dtype=torch.long))

    @property
    def training_perception(self) -> bool:
        """Whether the next training call is in the perception stage."""
        return int(self.step) < self.perception_steps

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        """Computes the weighted losses of the current stage (see class docstring)."""
        perception = self.training_perception
        if self.training:
            self.step += 1
        model = self.world_model
        if perception:
            first, current = _require(tensordict, [PIXELS_0, PIXELS], "V-CDN perception")
            loss_rec = self.rec_weight * model.reconstruction_error(first, current)
            return TensorDict({"loss_rec": loss_rec}, batch_size=[])
        current, following, action = _require(
            tensordict, [PIXELS, NEXT_PIXELS, ACTION], "V-CDN dynamics"
        )
        with torch.no_grad():  # the frozen perception module
            pos, next_pos = model.keypoints(torch.stack([current, following], dim=1)).unbind(1)
        edge_types, kl = model.inference(pos)
        predicted = model.dynamics(pos, edge_types, action)
        losses = {
            "loss_fwd": self.fwd_weight * keypoint_error(predicted, next_pos),
            "loss_kl": self.kl_weight * kl.mean(),
        }
        if self.rollout_weight > 0:
            frames, actions = _require(
                tensordict, [FUTURE_PIXELS, FUTURE_ACTION], "V-CDN rollout (trainer.horizon > 1)"
            )
            with torch.no_grad():
                target = model.keypoints(frames)  # [B, H - 1, K, 2]
            rollout = model.roll(predicted, edge_types, actions)
            losses["loss_rollout"] = self.rollout_weight * keypoint_error(rollout, target)
        return TensorDict(losses, batch_size=[])
