"""KINet as a ``torchrl.modules.WorldModel``: the keypoint scene graph, imagined pushes, a goal.

The encoder detects the keypoints ``x`` and features ``phi`` of the current image and the goal
graph of the goal image; the dynamics is the interaction net (features carried over, as in
training); the reward head is a goal objective of :data:`~kinet_rl.planners.OBJECTIVES` on the
predicted keypoints or graph. Every batch element can have its own goal.

Planning arithmetic (``fast``): the encoder embeds a goal image once (again when the image or the
model's weights change); a start state that all candidates share in memory (as
:class:`~kinet_rl.planners.GraphMPCPlanner` passes it) is encoded once per step, not once per
candidate; and the interaction net runs its fast edge layout
(:meth:`KeypointInteractionNet.forward`). The outputs are those of the straightforward
computation (``fast=False``) up to float rounding; ``bench/planner_flops.py`` compares both.

Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 3.4 (GraphMPC).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torch import Tensor, nn

from kinet_rl.keys import (
    ACTION,
    GOAL_KP_NODE_EMB,
    GOAL_KP_POS,
    GOAL_PIXELS,
    KP_FEAT,
    KP_NODE_EMB,
    KP_POS,
    KP_POS_EMB,
    PIXELS,
)
from kinet_rl.models.interaction import KeypointInteractionNet
from kinet_rl.models.keypoints import KeypointDetector
from kinet_rl.planners.objectives import goal_objective, goal_reward_head
from kinet_rl.planners.world_model import PushWorldModel, push_dynamics

#: What each keypoint-graph objective reads from the predicted next state.
KEYPOINT_OBJECTIVES = (
    "graph",
    "graph_dot",
    "graph_distance",
    "keypoints",
    "keypoints_l2",
    "keypoints_distance",
)


def narrow_broadcast_dims(*tensors: Tensor, event_dims: int) -> tuple[Tensor, ...]:
    """Views of ``tensors`` with each leading dim that is a broadcast in all of them narrowed to 1.

    A dim of stride 0 (e.g. the candidates of a planner that expanded one start state) holds the
    same values all along; computing on one slice and broadcasting gives the same result.

    Args:
        tensors: Tensors with the same leading (batch) dims.
        event_dims: Trailing dims of each tensor that are not batch dims.
    """
    for dim in range(tensors[0].dim() - event_dims):
        if tensors[0].shape[dim] > 1 and all(tensor.stride(dim) == 0 for tensor in tensors):
            tensors = tuple(tensor.narrow(dim, 0, 1) for tensor in tensors)
    return tensors


class GraphStep(nn.Module):
    """One imagined push with the interaction net: next keypoints, carried features, and the
    next graph's node embeddings the objective reads (``embed_positions``: those of the
    predicted keypoints, for ``graph_distance``).

    With ``fast``, a start graph shared by all candidates (stride 0, see
    :func:`narrow_broadcast_dims`) is passed to the interaction net once, which then computes
    what does not depend on the push once per plan step instead of once per candidate.
    """

    def __init__(
        self, interaction: KeypointInteractionNet, embed_positions: bool, fast: bool
    ) -> None:
        super().__init__()
        self.interaction = interaction
        self.embed_positions = embed_positions
        self.fast = fast

    def forward(self, pos: Tensor, feat: Tensor, action: Tensor) -> tuple[Tensor, ...]:
        graph = narrow_broadcast_dims(pos, feat, event_dims=2) if self.fast else (pos, feat)
        prediction = self.interaction(*graph, action, fast=self.fast)
        if self.embed_positions:
            nodes = self.interaction.embed_nodes(prediction.next_pos, feat)
        else:
            nodes = prediction.next_nodes
        return prediction.next_pos, feat, nodes


@dataclass(frozen=True, eq=False)
class _GoalGraph:
    """A goal image's keypoints ``[*G, K, 2]`` and node embeddings ``[*G, K, E]``, and what they
    were computed from (the image and a ``(data_ptr, version)`` stamp of every model tensor)."""

    pixels: Tensor
    weights: tuple[tuple[int, int], ...]
    pos: Tensor
    nodes: Tensor

    def matches(self, pixels: Tensor, weights: tuple[tuple[int, int], ...]) -> bool:
        """Whether this is the graph of the goal image ``pixels`` under the model ``weights``."""
        return (
            self.weights == weights
            and self.pixels.shape == pixels.shape
            and torch.equal(self.pixels, pixels)
        )


def check_goal_image(pixels: Tensor, goal_pixels: Tensor) -> None:
    """Raises a ValueError unless current and goal images ``[*B, H, W, 3]`` can be paired."""
    if pixels.dim() < 3 or pixels.shape[-1] != 3:
        raise ValueError(f"pixels must be [*B, H, W, 3] images, got {tuple(pixels.shape)}.")
    if goal_pixels.shape[-3:] != pixels.shape[-3:]:
        raise ValueError(
            f"goal image {tuple(goal_pixels.shape[-3:])} and current image "
            f"{tuple(pixels.shape[-3:])} must have the same [H, W, 3]; resize the goal image."
        )
    batch = pixels.shape[:-3]
    try:
        goal_fits = torch.broadcast_shapes(goal_pixels.shape[:-3], batch) == batch
    except RuntimeError:
        goal_fits = False
    if not goal_fits:
        raise ValueError(
            f"goal images {tuple(goal_pixels.shape)} do not broadcast to the current images' "
            f"batch {tuple(batch)}; pass one goal [H, W, 3] or one per image."
        )


class KeypointGraphEncoder(TensorDictModuleBase):
    """``PIXELS`` and ``GOAL_PIXELS`` -> keypoints, features and the goal graph (eval mode,
    no gradient); with ``fast``, a goal image's graph is kept while image and weights stay."""

    def __init__(
        self, detector: KeypointDetector, interaction: KeypointInteractionNet, fast: bool
    ) -> None:
        super().__init__()
        self.in_keys = [PIXELS, GOAL_PIXELS]
        self.out_keys = [KP_POS, KP_FEAT, GOAL_KP_NODE_EMB, GOAL_KP_POS]
        self.detector = detector
        self.interaction = interaction
        self.fast = fast
        self._goal: _GoalGraph | None = None

    @torch.no_grad()
    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        device = next(self.detector.parameters()).device
        pixels = tensordict.get(PIXELS).to(device)
        goal_pixels = tensordict.get(GOAL_PIXELS).to(device)
        check_goal_image(pixels, goal_pixels)
        batch = pixels.shape[:-3]
        modules = (self.detector, self.interaction)
        was_training = [module.training for module in modules]
        for module in modules:
            module.eval()
        pos, feat = self.detector(pixels)
        goal = self._goal_graph(goal_pixels)
        for module, training in zip(modules, was_training, strict=True):
            module.train(training)
        k = pos.shape[-2]
        tensordict.set(KP_POS, pos)
        tensordict.set(KP_FEAT, feat)
        tensordict.set(GOAL_KP_NODE_EMB, goal.nodes.expand(*batch, k, goal.nodes.shape[-1]).clone())
        tensordict.set(GOAL_KP_POS, goal.pos.expand(*batch, k, 2).clone())
        return tensordict

    def _goal_graph(self, goal_pixels: Tensor) -> _GoalGraph:
        weights = tuple(
            (tensor.data_ptr(), tensor._version)
            for module in (self.detector, self.interaction)
            for tensor in module.state_dict(keep_vars=True).values()
        )
        goal = self._goal
        if goal is None or not goal.matches(goal_pixels, weights):
            pos, feat = self.detector(goal_pixels)
            nodes = self.interaction.embed_nodes(pos, feat)
            goal = _GoalGraph(goal_pixels.clone(), weights, pos, nodes)
            if self.fast:
                self._goal = goal
        return goal


def keypoint_graph_world_model(
    detector: KeypointDetector,
    interaction: KeypointInteractionNet,
    objective: str,
    fast: bool = True,
) -> PushWorldModel:
    """KINet's world model (see the module docstring) planning with ``objective``.

    Keys:
        State: ``KP_POS`` ``[*B, K, 2]``, ``KP_FEAT`` ``[*B, K, D]``, ``GOAL_KP_NODE_EMB``
        ``[*B, K, E]``, ``GOAL_KP_POS`` ``[*B, K, 2]``; the dynamics also writes
        ``("next", KP_NODE_EMB)`` (or ``KP_POS_EMB``), which the graph objectives read.

    Args:
        detector: The trained keypoint detector.
        interaction: The trained interaction net.
        objective: One of :data:`KEYPOINT_OBJECTIVES`.
        fast: Plan with less arithmetic (see the module docstring); False runs the
            straightforward computation, the reference the fast one is tested against.
    """
    embeds = goal_objective(objective).state_key
    step = GraphStep(interaction, embed_positions=embeds == KP_POS_EMB, fast=fast)
    nodes_key = KP_POS_EMB if embeds == KP_POS_EMB else KP_NODE_EMB
    k, d, e = detector.num_keypoints, interaction.feat_dim, interaction.embed_dim
    return PushWorldModel(
        KeypointGraphEncoder(detector, interaction, fast),
        push_dynamics(
            step,
            [KP_POS, KP_FEAT, ACTION],
            [KP_POS, KP_FEAT, nodes_key],
            [GOAL_KP_NODE_EMB, GOAL_KP_POS],
        ),
        goal_reward_head(objective),
        {KP_POS: (k, 2), KP_FEAT: (k, d), GOAL_KP_NODE_EMB: (k, e), GOAL_KP_POS: (k, 2)},
    )
