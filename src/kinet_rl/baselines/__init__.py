"""Baselines of the KINet paper: Forw, ForwInv, IN, VisIN (Table I) and V-CDN, their world models,
and the oracle's analytic push model on ground-truth state; IN-full, IN on the full
ground-truth state (position, yaw and block geometry), is a stronger state-based ceiling.

Each model is an ``nn.Module`` with a TorchRL loss, ``object_rollout(geometry)`` for
forward-prediction evaluation and ``save_checkpoint``/``from_checkpoint``. See ``docs/baselines.md``.
"""

from __future__ import annotations

from kinet_rl.baselines.encoders import ConvEncoder, crop_objects
from kinet_rl.baselines.image_models import (
    FeatureObjectRollout,
    ImageForwardInverseModel,
    ImageForwardModel,
    MotionProbe,
)
from kinet_rl.baselines.imagination import (
    feature_world_model,
    object_world_model,
    vcdn_world_model,
)
from kinet_rl.baselines.losses import (
    ImageForwardLoss,
    ObjectForwardLoss,
    VCDNLoss,
    feature_info_nce,
)
from kinet_rl.baselines.object_models import (
    FullStateInteractionModel,
    ObjectCountError,
    ObjectInteractionModel,
    ObjectStateRollout,
    VisualInteractionModel,
)
from kinet_rl.baselines.oracle import AnalyticPushModel, analytic_push
from kinet_rl.baselines.vcdn import EdgeTypeDynamics, EdgeTypeInference, VCDNWorldModel
from kinet_rl.models.checkpointing import ConfigCheckpointMixin

__all__ = [
    "AnalyticPushModel",
    "ConfigCheckpointMixin",
    "ConvEncoder",
    "EdgeTypeDynamics",
    "EdgeTypeInference",
    "FeatureObjectRollout",
    "FullStateInteractionModel",
    "ImageForwardInverseModel",
    "ImageForwardLoss",
    "ImageForwardModel",
    "MotionProbe",
    "ObjectCountError",
    "ObjectForwardLoss",
    "ObjectInteractionModel",
    "ObjectStateRollout",
    "VCDNLoss",
    "VCDNWorldModel",
    "VisualInteractionModel",
    "analytic_push",
    "crop_objects",
    "feature_info_nce",
    "feature_world_model",
    "object_world_model",
    "vcdn_world_model",
]
