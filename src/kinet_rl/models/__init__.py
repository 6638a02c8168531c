"""KINet: keypoint detector and reconstruction, probabilistic graph forward model, losses, and
its model env and push planner for goal-conditioned control."""

from __future__ import annotations

from kinet_rl.atomic import CheckpointError
from kinet_rl.models.interaction import (
    GraphPrediction,
    KeypointInteractionNet,
    edge_geometry,
    graph_similarity,
)
from kinet_rl.models.keypoints import KeypointDetector, KeypointReconstructor
from kinet_rl.models.losses import KINetLoss, graph_info_nce
from kinet_rl.models.model_env import (
    REWARDS,
    GraphDistanceReward,
    GraphSimilarityReward,
    KeypointChamferReward,
    KeypointDistanceReward,
    KeypointL2Reward,
    KINetModelEnv,
    KINetReward,
    chamfer_distance,
)
from kinet_rl.models.pretrained import model_card, pretrained_names
from kinet_rl.models.push_planner import Push, PushPlanner
from kinet_rl.models.transforms import KeypointTransform
from kinet_rl.models.world_model import KINetWorldModel, TransitionOutputs

__all__ = [
    "REWARDS",
    "CheckpointError",
    "GraphDistanceReward",
    "GraphPrediction",
    "GraphSimilarityReward",
    "KINetLoss",
    "KINetModelEnv",
    "KINetReward",
    "KINetWorldModel",
    "KeypointChamferReward",
    "KeypointDistanceReward",
    "KeypointL2Reward",
    "KeypointDetector",
    "KeypointInteractionNet",
    "KeypointReconstructor",
    "KeypointTransform",
    "Push",
    "PushPlanner",
    "TransitionOutputs",
    "chamfer_distance",
    "edge_geometry",
    "graph_info_nce",
    "graph_similarity",
    "model_card",
    "pretrained_names",
]
