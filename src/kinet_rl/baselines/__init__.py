"""Baseline forward models of the KINet paper (Table I): Forw, ForwInv, IN and VisIN.

Each is an ``nn.Module`` with a TorchRL loss, ``object_rollout(geometry)`` for forward-prediction
evaluation and ``save_checkpoint``/``from_checkpoint``. See ``docs/baselines.md``.
"""

from __future__ import annotations

from kinet_rl.baselines.encoders import ConvEncoder, crop_objects
from kinet_rl.baselines.image_models import (
    IMAGE_FEAT,
    FeatureObjectRollout,
    ImageForwardInverseModel,
    ImageForwardModel,
    MotionProbe,
)
from kinet_rl.baselines.losses import ImageForwardLoss, ObjectForwardLoss, feature_info_nce
from kinet_rl.baselines.object_models import (
    ObjectCountError,
    ObjectInteractionModel,
    ObjectStateRollout,
    VisualInteractionModel,
)
from kinet_rl.baselines.toy_pushing import ToyPushData
from kinet_rl.models.checkpointing import ConfigCheckpointMixin

__all__ = [
    "IMAGE_FEAT",
    "ConfigCheckpointMixin",
    "ConvEncoder",
    "FeatureObjectRollout",
    "ImageForwardInverseModel",
    "ImageForwardLoss",
    "ImageForwardModel",
    "MotionProbe",
    "ObjectCountError",
    "ObjectForwardLoss",
    "ObjectInteractionModel",
    "ObjectStateRollout",
    "ToyPushData",
    "VisualInteractionModel",
    "crop_objects",
    "feature_info_nce",
]
