"""KINet: keypoint detector and reconstruction, probabilistic graph forward model, losses, and
its world model for planning and the push planner for goal-conditioned control."""

from __future__ import annotations

from kinet_rl.atomic import CheckpointError
from kinet_rl.models.imagination import KEYPOINT_OBJECTIVES, keypoint_graph_world_model
from kinet_rl.models.interaction import (
    GraphPrediction,
    KeypointInteractionNet,
    edge_geometry,
    graph_similarity,
)
from kinet_rl.models.keypoints import KeypointDetector, KeypointReconstructor
from kinet_rl.models.losses import KINetLoss, graph_info_nce
from kinet_rl.models.pretrained import model_card, pretrained_names
from kinet_rl.models.push_planner import Push, PushPlanner
from kinet_rl.models.transforms import KeypointTransform
from kinet_rl.models.world_model import KINetWorldModel, TransitionOutputs

__all__ = [
    "KEYPOINT_OBJECTIVES",
    "CheckpointError",
    "GraphPrediction",
    "KINetLoss",
    "KINetWorldModel",
    "KeypointDetector",
    "KeypointInteractionNet",
    "KeypointReconstructor",
    "KeypointTransform",
    "Push",
    "PushPlanner",
    "TransitionOutputs",
    "edge_geometry",
    "graph_info_nce",
    "graph_similarity",
    "keypoint_graph_world_model",
    "model_card",
    "pretrained_names",
]
