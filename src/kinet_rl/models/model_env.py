"""KINet as a TorchRL model env: imagined pushes on the keypoint scene graph, scored against a goal.

Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 3.4 (GraphMPC).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import torch
import torch.nn.functional as F
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule
from torch import Tensor, nn

from kinet_rl.keys import (
    ACTION,
    GOAL_KP_NODE_EMB,
    GOAL_KP_POS,
    GOAL_PIXELS,
    KP_FEAT,
    KP_POS,
    PIXELS,
    STEP_REWARD,
)
from kinet_rl.models.interaction import GraphPrediction, KeypointInteractionNet, graph_similarity
from kinet_rl.models.world_model import KINetWorldModel
from kinet_rl.planners.model_env import StateModelEnv, check_goal_image


def chamfer_distance(pos: Tensor, goal_pos: Tensor) -> Tensor:
    """Symmetric Chamfer distance ``[*B]`` between point sets ``[*B, K, 2]`` and ``[*B, M, 2]``.

    The mean over points of the distance to the nearest point of the other set, averaged over
    both directions; it needs no correspondence between the sets.
    """
    dist = torch.cdist(pos, goal_pos.expand(*pos.shape[:-2], *goal_pos.shape[-2:]))  # [*B, K, M]
    return 0.5 * (dist.min(-1).values.mean(-1) + dist.min(-2).values.mean(-1))


class KINetReward(Protocol):
    """A goal reward of :class:`KINetModelEnv`, computed from one imagined push.

    Called with the interaction net, its prediction for the push, the carried keypoint features
    ``[*B, K, D]``, the goal graph's node embeddings ``[*B, K, E]`` and the goal keypoints
    ``[*B, K, 2]``; returns ``[*B]`` (larger is closer to the goal).
    """

    def __call__(
        self,
        interaction: KeypointInteractionNet,
        prediction: GraphPrediction,
        feat: Tensor,
        goal_nodes: Tensor,
        goal_pos: Tensor,
    ) -> Tensor: ...


class GraphSimilarityReward:
    """GraphMPC's objective: the similarity ``S`` of the predicted next graph to the goal graph.

    ``S`` compares matching node embeddings (keypoint ``k`` of the prediction against keypoint
    ``k`` of the goal image: the detector's keypoint channels are consistent across images). The
    prediction's embeddings are the interaction net's predicted next nodes, the goal's are
    ``embed_nodes`` of the goal keypoints: the pair the contrastive loss aligns. With
    ``similarity="dot"`` it is the paper's ``S / K = (1/K) sum_k n_k . n_goal_k`` (unbounded: a
    candidate can raise it by inflating its embeddings along the goal's); ``"cosine"`` (default)
    is the cosine of the two flattened graphs, the bounded logit the contrastive loss trains
    (``loss.ctr_similarity=cosine``, paper Sec. 3.4-3.5 with normalised embeddings).

    Args:
        similarity: ``"cosine"`` or ``"dot"``; use the one the model's contrastive loss used.
    """

    def __init__(self, similarity: str = "cosine") -> None:
        if similarity not in ("cosine", "dot"):
            raise ValueError(f"similarity={similarity!r}; choose 'cosine' or 'dot'.")
        self.similarity = similarity

    def __call__(self, interaction, prediction, feat, goal_nodes, goal_pos) -> Tensor:
        nodes = prediction.next_nodes
        if self.similarity == "dot":
            return graph_similarity(nodes, goal_nodes) / goal_nodes.shape[-2]
        return F.cosine_similarity(nodes.flatten(-2), goal_nodes.flatten(-2), dim=-1)


class GraphDistanceReward:
    """Minus the mean squared distance between predicted and goal node embeddings.

    ``-(1/K) sum_k |n_hat_k - n_goal_k|^2`` with ``n_hat`` the ``embed_nodes`` of the predicted
    keypoints and the carried features. Not in the paper: ``S`` alone rewards embeddings that
    grow along the goal's, a distance only a match; in docs/results.md it plans better than
    :class:`GraphSimilarityReward` and :class:`KeypointChamferReward`.
    """

    def __call__(self, interaction, prediction, feat, goal_nodes, goal_pos) -> Tensor:
        nodes = interaction.embed_nodes(prediction.next_pos, feat)
        return -(nodes - goal_nodes).pow(2).sum(-1).mean(-1)


class KeypointChamferReward:
    """MPC on keypoint positions only: minus the symmetric Chamfer distance to the goal keypoints.

    In image units (``[-1, 1]``); no graph embedding is used.
    """

    def __call__(self, interaction, prediction, feat, goal_nodes, goal_pos) -> Tensor:
        return -chamfer_distance(prediction.next_pos, goal_pos)


class KeypointL2Reward:
    """MPC on index-matched keypoint positions: minus the mean over keypoints of ``|x_k - g_k|^2``.

    Keypoint ``k`` of the prediction is compared with keypoint ``k`` of the goal image (the
    correspondence the graph rewards rely on), without any embedding: the control that shows what
    the graph embedding adds to GraphMPC.
    """

    def __call__(self, interaction, prediction, feat, goal_nodes, goal_pos) -> Tensor:
        return -(prediction.next_pos - goal_pos).pow(2).sum(-1).mean(-1)


class KeypointDistanceReward:
    """Minus the mean over keypoints of the distance ``|x_k - g_k|`` (not squared).

    The index-matched keypoint cost of :class:`KeypointL2Reward` with the robustness of V-CDN's
    cost (``kinet_rl.baselines.model_env``): a keypoint that the detector placed far from its goal
    counterpart (on the table in one image, on an object in the other) weighs in linearly, so it
    does not dominate the choice of push.
    """

    def __call__(self, interaction, prediction, feat, goal_nodes, goal_pos) -> Tensor:
        return -(prediction.next_pos - goal_pos).norm(dim=-1).mean(-1)


#: The rewards by their command-line names (``python -m kinet_rl.plan --reward``).
REWARDS: dict[str, type[KINetReward]] = {
    "graph": GraphSimilarityReward,
    "graph_distance": GraphDistanceReward,
    "keypoints": KeypointChamferReward,
    "keypoints_l2": KeypointL2Reward,
    "keypoints_distance": KeypointDistanceReward,
}


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


class _GraphStep(nn.Module):
    """One imagined push with the interaction net; reward from the predicted next graph.

    With ``fast``, a start graph shared by all candidates (stride 0, see
    :func:`narrow_broadcast_dims`) is passed to the interaction net once, which then computes
    what does not depend on the push once per plan step instead of once per candidate.
    """

    def __init__(
        self, interaction: KeypointInteractionNet, reward: KINetReward, fast: bool
    ) -> None:
        super().__init__()
        self.interaction = interaction
        self.reward = reward
        self.fast = fast

    def forward(
        self, pos: Tensor, feat: Tensor, action: Tensor, goal_nodes: Tensor, goal_pos: Tensor
    ) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
        graph = narrow_broadcast_dims(pos, feat, event_dims=2) if self.fast else (pos, feat)
        prediction = self.interaction(*graph, action, fast=self.fast)
        reward = self.reward(self.interaction, prediction, feat, goal_nodes, goal_pos)
        return prediction.next_pos, feat, reward.unsqueeze(-1), goal_nodes, goal_pos


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


class KINetModelEnv(StateModelEnv):
    """Imagined pushing with a trained KINet; state = keypoint scene graph, action = 4-d push.

    Each step predicts the next keypoints with the interaction net (features carried over, as
    in training) and writes a goal reward computed from the predicted next graph by a
    :class:`KINetReward`: :class:`GraphSimilarityReward` (the paper's ``S``),
    :class:`GraphDistanceReward` (node-embedding distance) or :class:`KeypointChamferReward`.

    The goal travels in the tensordict (``GOAL_KP_NODE_EMB``, ``GOAL_KP_POS``), so every batch
    element can have its own. The env is not batch-locked and runs the model without gradient
    in eval mode (mean edge logits) when used by a planner.

    Planning arithmetic (``fast``): :meth:`observe` embeds a goal image once (again when the image
    or the model's weights change); a start state that all candidates share in memory (as
    :class:`~kinet_rl.planners.GraphMPCPlanner` passes it) is encoded once per step, not once per
    candidate; and the interaction net runs its fast edge layout
    (:meth:`KeypointInteractionNet.forward`). The outputs are those of the straightforward
    computation (``fast=False``) up to float rounding; ``bench/planner_flops.py`` compares both.

    Keys:
        State/observation: ``KP_POS`` ``[*B, K, 2]``, ``KP_FEAT`` ``[*B, K, D]``,
        ``GOAL_KP_NODE_EMB`` ``[*B, K, E]``, ``GOAL_KP_POS`` ``[*B, K, 2]``. Action ``[*B, 4]``
        in ``[-1, 1]``. Reward ``[*B, 1]``.

    Args:
        model: A trained :class:`KINetWorldModel`.
        reward: The goal reward (default: the paper's ``S``).
        fast: Plan with less arithmetic (see above); False runs the straightforward computation,
            the reference the fast one is tested and benchmarked against.
    """

    def __init__(
        self, model: KINetWorldModel, reward: KINetReward | None = None, fast: bool = True
    ) -> None:
        if reward is not None and not callable(reward):
            raise TypeError(
                f"reward must be a KINetReward object, got {reward!r}; pass e.g. "
                f"GraphDistanceReward() (by name: REWARDS[name]() with a name of {sorted(REWARDS)})."
            )
        self.reward = GraphSimilarityReward() if reward is None else reward
        step = TensorDictModule(
            _GraphStep(model.interaction, self.reward, fast),
            in_keys=[KP_POS, KP_FEAT, ACTION, GOAL_KP_NODE_EMB, GOAL_KP_POS],
            out_keys=[KP_POS, KP_FEAT, STEP_REWARD, GOAL_KP_NODE_EMB, GOAL_KP_POS],
        )
        cfg = model.config
        k, d, e = cfg["num_keypoints"], cfg["feat_dim"], cfg["embed_dim"]
        super().__init__(
            step,
            {KP_POS: (k, 2), KP_FEAT: (k, d), GOAL_KP_NODE_EMB: (k, e), GOAL_KP_POS: (k, 2)},
            reset_hint="env.observe(pixels, goal_pixels) builds it, or pass 'pixels' and "
            "('goal', 'pixels').",
        )
        self.model = model
        self.fast = fast
        self._goal: _GoalGraph | None = None

    @torch.no_grad()
    def observe(self, pixels: Tensor, goal_pixels: Tensor) -> TensorDict:
        """The start state for a planner: keypoints of ``pixels`` and the goal graph of ``goal_pixels``.

        Args:
            pixels: uint8 ``[*B, H, W, 3]`` current images.
            goal_pixels: uint8 ``[*B, H, W, 3]`` goal images (or one ``[H, W, 3]`` for all).

        Returns:
            A ``[*B]`` tensordict with the state keys.
        """
        pixels = pixels.to(self.device)
        goal_pixels = goal_pixels.to(self.device)
        if pixels.dim() < 3 or pixels.shape[-1] != 3:
            raise ValueError(f"pixels must be [*B, H, W, 3] images, got {tuple(pixels.shape)}.")
        check_goal_image(pixels, goal_pixels)
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
        was_training = self.model.training
        self.model.eval()
        pos, feat = self.model.detector(pixels)
        goal = self._goal_graph(goal_pixels)
        self.model.train(was_training)
        k = pos.shape[-2]
        goal_nodes = goal.nodes.expand(*batch, k, goal.nodes.shape[-1]).clone()
        goal_pos = goal.pos.expand(*batch, k, 2).clone()
        return TensorDict(
            {KP_POS: pos, KP_FEAT: feat, GOAL_KP_NODE_EMB: goal_nodes, GOAL_KP_POS: goal_pos},
            batch_size=batch,
            device=self.device,
        )

    def _goal_graph(self, goal_pixels: Tensor) -> _GoalGraph:
        """The goal's keypoints and embeddings; with ``fast``, kept while image and model stay."""
        weights = tuple(
            (tensor.data_ptr(), tensor._version)
            for tensor in self.model.state_dict(keep_vars=True).values()
        )
        goal = self._goal
        if goal is None or not goal.matches(goal_pixels, weights):
            pos, feat = self.model.detector(goal_pixels)
            nodes = self.model.interaction.embed_nodes(pos, feat)
            goal = _GoalGraph(goal_pixels.clone(), weights, pos, nodes)
            if self.fast:
                self._goal = goal
        return goal

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        if tensordict is not None and KP_POS not in tensordict.keys(True):
            pixels, goal = tensordict.get(PIXELS, None), tensordict.get(GOAL_PIXELS, None)
            if pixels is not None and goal is not None:
                return self.observe(pixels, goal)
        return super()._reset(tensordict, **kwargs)
