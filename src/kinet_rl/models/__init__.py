"""KINet: keypoint detector and reconstruction, probabilistic graph forward model, losses."""

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
from kinet_rl.models.transforms import KeypointTransform
from kinet_rl.models.world_model import KINetWorldModel, TransitionOutputs

__all__ = [
    "CheckpointError",
    "GraphPrediction",
    "KINetLoss",
    "KINetWorldModel",
    "KeypointDetector",
    "KeypointInteractionNet",
    "KeypointReconstructor",
    "KeypointTransform",
    "TransitionOutputs",
    "edge_geometry",
    "graph_info_nce",
    "graph_similarity",
]
