"""Baselines of the KINet paper: Forw, ForwInv, IN, VisIN (Table I) and V-CDN, their model envs,
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
from kinet_rl.baselines.losses import (
    ImageForwardLoss,
    ObjectForwardLoss,
    VCDNLoss,
    feature_info_nce,
)
from kinet_rl.baselines.model_env import (
    FeatureModelEnv,
    KeypointGraphModelEnv,
    ObjectModelEnv,
    make_baseline_env,
)
from kinet_rl.baselines.object_models import (
    FullStateInteractionModel,
    ObjectCountError,
    ObjectInteractionModel,
    ObjectStateRollout,
    VisualInteractionModel,
)
from kinet_rl.baselines.oracle import AnalyticPushModelEnv, analytic_push
from kinet_rl.baselines.toy_pushing import ToyPushData
from kinet_rl.baselines.vcdn import EdgeTypeDynamics, EdgeTypeInference, VCDNWorldModel
from kinet_rl.models.checkpointing import ConfigCheckpointMixin

__all__ = [
    "AnalyticPushModelEnv",
    "ConfigCheckpointMixin",
    "ConvEncoder",
    "EdgeTypeDynamics",
    "EdgeTypeInference",
    "FeatureModelEnv",
    "FeatureObjectRollout",
    "FullStateInteractionModel",
    "ImageForwardInverseModel",
    "ImageForwardLoss",
    "ImageForwardModel",
    "KeypointGraphModelEnv",
    "MotionProbe",
    "ObjectCountError",
    "ObjectForwardLoss",
    "ObjectInteractionModel",
    "ObjectModelEnv",
    "ObjectStateRollout",
    "ToyPushData",
    "VCDNLoss",
    "VCDNWorldModel",
    "VisualInteractionModel",
    "analytic_push",
    "crop_objects",
    "feature_info_nce",
    "make_baseline_env",
]
