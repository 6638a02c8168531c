"""KINet as a TorchRL model env: imagined pushes on the keypoint scene graph, scored against a goal.

Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 3.4 (GraphMPC).
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule
from torch import Tensor, nn
from torchrl.data import Bounded, Composite, Unbounded
from torchrl.envs.model_based import ModelBasedEnvBase

from kinet_rl.keys import (
    ACTION,
    GOAL_KP_NODE_EMB,
    GOAL_KP_POS,
    KP_FEAT,
    KP_POS,
    PIXELS,
)
from kinet_rl.models import KINetWorldModel
from kinet_rl.models.interaction import KeypointInteractionNet, graph_similarity
from kinet_rl.planners import GraphMPCPlanner

REWARDS = ("graph", "graph_distance", "keypoints")


def chamfer_distance(pos: Tensor, goal_pos: Tensor) -> Tensor:
    """Symmetric Chamfer distance ``[*B]`` between point sets ``[*B, K, 2]`` and ``[*B, M, 2]``.

    The mean over points of the distance to the nearest point of the other set, averaged over
    both directions; it needs no correspondence between the sets.
    """
    dist = torch.cdist(pos, goal_pos.expand(*pos.shape[:-2], *goal_pos.shape[-2:]))  # [*B, K, M]
    return 0.5 * (dist.min(-1).values.mean(-1) + dist.min(-2).values.mean(-1))


class _GraphStep(nn.Module):
    """One imagined push with the interaction net; reward from the predicted next graph."""

    def __init__(self, interaction: KeypointInteractionNet, reward: str) -> None:
        super().__init__()
        self.interaction = interaction
        self.reward = reward

    def forward(
        self, pos: Tensor, feat: Tensor, action: Tensor, goal_nodes: Tensor, goal_pos: Tensor
    ) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
        prediction = self.interaction(pos, feat, action)
        if self.reward == "graph":  # S(G_pred, G_goal) / K, Sec. 3.4
            reward = graph_similarity(prediction.next_nodes, goal_nodes) / pos.shape[-2]
        elif self.reward == "graph_distance":
            nodes = self.interaction.embed_nodes(prediction.next_pos, feat)
            reward = -(nodes - goal_nodes).pow(2).sum(-1).mean(-1)
        else:
            reward = -chamfer_distance(prediction.next_pos, goal_pos)
        return prediction.next_pos, feat, reward.unsqueeze(-1), goal_nodes, goal_pos


class KINetModelEnv(ModelBasedEnvBase):
    """Imagined pushing with a trained KINet; state = keypoint scene graph, action = 4-d push.

    Each step predicts the next keypoints with the interaction net (features carried over, as
    in training) and writes a goal reward computed from the predicted next graph:

    * ``reward="graph"`` (GraphMPC): ``S(G_pred, G_goal) / K`` where ``S`` sums the dot products
      of matching node embeddings (keypoint ``k`` of the prediction against keypoint ``k`` of
      the goal image: the detector's keypoint channels are consistent across images). The
      prediction's embeddings are the interaction net's predicted next nodes, the goal's are
      ``embed_nodes`` of the goal keypoints: the pair the contrastive loss aligns. Dividing by
      ``K`` only rescales (it matters for MPPI's temperature, not for CEM).
    * ``reward="graph_distance"``: minus the mean squared distance between the node embeddings
      of the predicted next graph, ``embed_nodes`` of the predicted keypoints and the carried
      features, and the goal's: ``-(1/K) sum_k |n_hat_k - n_goal_k|^2``. Not in the paper:
      ``S`` alone rewards embeddings that grow along the goal's, a distance only a match; in
      docs/results.md it plans better than ``"graph"`` and ``"keypoints"``.
    * ``reward="keypoints"`` (MPC on keypoint positions only): minus the symmetric Chamfer
      distance between predicted and goal keypoint positions (image units, ``[-1, 1]``).

    The goal travels in the tensordict (``GOAL_KP_NODE_EMB``, ``GOAL_KP_POS``), so every batch
    element can have its own. The env is not batch-locked and runs the model without gradient
    in eval mode (mean edge logits) when used by a planner.

    Keys:
        State/observation: ``KP_POS`` ``[*B, K, 2]``, ``KP_FEAT`` ``[*B, K, D]``,
        ``GOAL_KP_NODE_EMB`` ``[*B, K, E]``, ``GOAL_KP_POS`` ``[*B, K, 2]``. Action ``[*B, 4]``
        in ``[-1, 1]``. Reward ``[*B, 1]``.

    Args:
        model: A trained :class:`KINetWorldModel`.
        reward: ``"graph"``, ``"graph_distance"`` or ``"keypoints"``.
    """

    def __init__(self, model: KINetWorldModel, reward: str = "graph") -> None:
        if reward not in REWARDS:
            raise ValueError(f"reward must be one of {REWARDS}, got {reward!r}.")
        step = TensorDictModule(
            _GraphStep(model.interaction, reward),
            in_keys=[KP_POS, KP_FEAT, ACTION, GOAL_KP_NODE_EMB, GOAL_KP_POS],
            out_keys=[KP_POS, KP_FEAT, "reward", GOAL_KP_NODE_EMB, GOAL_KP_POS],
        )
        device = next(model.parameters()).device
        super().__init__(step, device=device, batch_size=torch.Size([]))
        self.model = model
        self.reward = reward
        cfg = model.config
        k, d, e = cfg["num_keypoints"], cfg["feat_dim"], cfg["embed_dim"]
        state = Composite(
            {
                KP_POS: Unbounded((k, 2), device=device),
                KP_FEAT: Unbounded((k, d), device=device),
                GOAL_KP_NODE_EMB: Unbounded((k, e), device=device),
                GOAL_KP_POS: Unbounded((k, 2), device=device),
            },
            device=device,
        )
        self.observation_spec = state.clone()
        self.state_spec = state
        self.action_spec = Bounded(-1.0, 1.0, (4,), device=device)
        self.reward_spec = Unbounded((1,), device=device)

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
        if goal_pixels.shape[-3:] != pixels.shape[-3:]:
            raise ValueError(
                f"goal image {tuple(goal_pixels.shape[-3:])} and current image "
                f"{tuple(pixels.shape[-3:])} must have the same [H, W, 3]; resize the goal image."
            )
        batch = pixels.shape[:-3]
        goal_pixels = goal_pixels.expand(*batch, *goal_pixels.shape[-3:])
        was_training = self.model.training
        self.model.eval()
        pos, feat = self.model.detector(pixels)
        goal_pos, goal_feat = self.model.detector(goal_pixels)
        goal_nodes = self.model.interaction.embed_nodes(goal_pos, goal_feat)
        self.model.train(was_training)
        return TensorDict(
            {KP_POS: pos, KP_FEAT: feat, GOAL_KP_NODE_EMB: goal_nodes, GOAL_KP_POS: goal_pos},
            batch_size=batch,
            device=self.device,
        )

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        if tensordict is not None and KP_POS in tensordict.keys(True):
            return tensordict.select(*self.state_spec.keys(True, True)).clone()
        if tensordict is None or PIXELS not in tensordict.keys():  # noqa: SIM118 (TensorDict)
            raise KeyError(
                "KINetModelEnv.reset needs a tensordict with the state keys, or with 'pixels' "
                "and ('goal', 'pixels'); env.observe(pixels, goal_pixels) builds the state."
            )
        return self.observe(tensordict.get(PIXELS), tensordict.get(("goal", PIXELS)))


def make_kinet_planner(
    model: KINetWorldModel, reward: str = "graph", **planner_kwargs
) -> GraphMPCPlanner:
    """A :class:`GraphMPCPlanner` over a :class:`KINetModelEnv` of ``model`` (put in eval mode)."""
    model.eval()
    return GraphMPCPlanner(KINetModelEnv(model, reward=reward), **planner_kwargs)
