"""TensorDict keys shared by more than one module.

Shapes use: B batch, T time, K keypoints, N objects, D features, H/W image.
Transitions follow TorchRL's ``("next", key)`` convention; predictions are written to the
same keys under ``"next"``. The env's observation dicts (dm_control) use the same root names.
"""

from __future__ import annotations

PIXELS = "pixels"  # uint8 [*B, H, W, 3] from the env
ACTION = "action"  # float32 [*B, 4] push (start x, start y, end x, end y) in [-1, 1]
OBJECT_POS = "object_pos"  # float32 [*B, N, 2] metres, table frame (evaluation only)
OBJECT_YAW = "object_yaw"  # float32 [*B, N] radians (evaluation only)
#: float32 [*B, N, 8] metres: each object's body-frame footprint as two boxes, each (centre x,
#: centre y, half extent x, half extent y); constant within an episode (IN-full, evaluation)
OBJECT_SHAPE = "object_shape"
#: int64 [*B] objects in the episode's scene; stored by variable-count datasets, whose
#: per-object arrays hold NaN for the objects beyond it (:mod:`kinet_rl.data.object_counts`)
OBJECT_COUNT = "num_objects"
UNSTABLE = "unstable"  # bool [*B, 1] the simulation went unstable; the episode ended
STEP_REWARD = "reward"  # [*B, 1] written by a model env's step module (TorchRL nests it)
REWARD = ("next", STEP_REWARD)  # [*B, 1]
NEXT_PIXELS = ("next", PIXELS)
NEXT_OBJECT_POS = ("next", OBJECT_POS)

PIXELS_0 = "pixels_0"  # uint8 [*B, H, W, 3] first frame I_0 of the transition's episode
EPISODE = "episode"  # int64 [*B] episode index within a dataset
STEP = "step"  # int64 [*B] push index within its episode
FUTURE_ACTION = ("future", ACTION)  # float32 [*B, H - 1, 4] the pushes after a transition's
FUTURE_PIXELS = ("future", PIXELS)  # uint8 [*B, H - 1, H, W, 3] the frames after those pushes

KP_POS = ("keypoints", "pos")  # float32 [*B, K, 2] image coordinates in [-1, 1]
KP_FEAT = ("keypoints", "feat")  # float32 [*B, K, D]
KP_NODE_EMB = ("keypoints", "node_emb")  # float32 [*B, K, E] scene-graph node embeddings
#: float32 [*B, K, E] node embeddings of the keypoints as they are (no message passing): what the
#: goal graph's nodes are, so a predicted state compares with them (the graph_distance objective)
KP_POS_EMB = ("keypoints", "pos_emb")
KP_EDGE_TYPE = ("keypoints", "edge_type")  # float32 [*B, K, K - 1, C] edge-type probs (V-CDN)
GOAL_PIXELS = ("goal", PIXELS)  # uint8 [*B, H, W, 3] goal image
GOAL_KP_POS = ("goal", "keypoints", "pos")
GOAL_KP_NODE_EMB = ("goal", "keypoints", "node_emb")  # float32 [*B, K, E] goal-graph nodes
GOAL_OBJECT_POS = ("goal", OBJECT_POS)  # float32 [*B, N, 2] metres, goal of GT-state planners
GOAL_DISTANCE = "goal_distance"  # float64 [*B] metres: mean object distance to its goal (episodes)
GOAL_SSIM = "goal_ssim"  # float64 [*B] SSIM of the camera image to the goal image (episodes)
OBJECT_FEAT = ("objects", "feat")  # float32 [*B, N, F] per-object visual features (VisIN)
IMAGE_FEAT = ("image", "feat")  # float32 [*B, D] whole-image feature z (Forw/ForwInv)
GOAL_IMAGE_FEAT = ("goal", "image", "feat")  # float32 [*B, D] goal-image feature (Forw/ForwInv)
