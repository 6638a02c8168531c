"""V-CDN: keypoints of a pretrained, frozen detector, an inferred graph of edge types and
push-conditioned dynamics on keypoint positions only.

* Perception: KINet's :class:`~kinet_rl.models.keypoints.KeypointDetector` without visual features
  (``feat_dim = 0``) and its Transporter reconstructor, trained first by reconstruction alone
  and frozen after (the two stages of :class:`~kinet_rl.baselines.losses.VCDNLoss`).
* Inference (:class:`EdgeTypeInference`): a categorical posterior over ``C`` edge types for every
  pair of keypoints, computed from their positions; type 0 means "no relation".
* Dynamics (:class:`EdgeTypeDynamics`): node embeddings of the positions plus an encoding of the
  push relative to each keypoint; ``L`` rounds of messages of one kind per relation type, weighted
  by the edge-type probabilities; a decoder predicts each keypoint's displacement.

Reference: Li et al., "Causal Discovery in Physical Systems from Videos", NeurIPS 2020; KINet,
Rezazadeh et al., RA-L 2023, Sec. 4-5 (V-CDN conditioned on the push).
"""

from __future__ import annotations

import math
from typing import Any

import torch
import torch.nn.functional as F
from tensordict import TensorDictBase
from torch import Tensor, nn

from kinet_rl.baselines.imagination import vcdn_world_model
from kinet_rl.keys import ACTION, GOAL_PIXELS, KP_EDGE_TYPE, KP_POS, PIXELS
from kinet_rl.models.checkpointing import ConfigCheckpointMixin
from kinet_rl.models.interaction import (
    PUSH_FEATURE_DIM,
    edge_geometry,
    edge_layout,
    mlp,
    push_batch,
    push_features,
)
from kinet_rl.models.keypoint_model import KeypointWorldModel
from kinet_rl.models.keypoints import KeypointDetector, KeypointReconstructor, pixels_to_input
from kinet_rl.planners.world_model import (
    ModelCapabilities,
    PlanningDefaults,
    PushWorldModel,
    check_objective,
)

#: Size of :func:`~kinet_rl.models.interaction.edge_geometry`'s raw edge features.
EDGE_GEOMETRY_DIM = 3
#: Temperature of the Gumbel-softmax edge-type samples in training (V-CDN's).
GUMBEL_TEMPERATURE = 0.5


def check_edge_types(num_edge_types: int) -> None:
    """Raises a ValueError unless there is "no relation" and at least one relation type."""
    if num_edge_types < 2:
        raise ValueError(
            f"num_edge_types must be >= 2 (type 0 is 'no relation'), got {num_edge_types}."
        )


class EdgeTypeInference(nn.Module):
    """V-CDN's inference module: a distribution over edge types for every pair of keypoints.

    Nodes embed positions, edges ``[x_i - x_j, |x_i - x_j|^2]``; an MLP of ``[n_i, n_k, e_ik]``
    gives ``C`` logits per edge, symmetrised over ``(i, k)``. In training the edge types are
    Gumbel-softmax samples (temperature :data:`GUMBEL_TEMPERATURE`), in eval mode the posterior
    probabilities. ``kl`` is the posterior's KL to the uniform prior, averaged over edges.

    Reference: Li et al., NeurIPS 2020, Sec. 3.2 (here from one frame's keypoints, not a video).

    Args:
        num_edge_types: ``C``, including type 0 ("no relation").
        embed_dim: ``E`` of node and edge embeddings.
        hidden_dim: Hidden units of every MLP.
        num_hidden: Hidden layers of every MLP.
    """

    def __init__(
        self,
        num_edge_types: int = 3,
        embed_dim: int = 64,
        hidden_dim: int = 128,
        num_hidden: int = 3,
    ) -> None:
        super().__init__()
        check_edge_types(num_edge_types)
        self.num_edge_types = num_edge_types
        self.node_encoder = mlp(2, embed_dim, hidden_dim, num_hidden)
        self.edge_encoder = mlp(EDGE_GEOMETRY_DIM, embed_dim, hidden_dim, num_hidden)
        self.edge_logits = mlp(3 * embed_dim, num_edge_types, hidden_dim, num_hidden)

    def forward(self, pos: Tensor) -> tuple[Tensor, Tensor]:
        """Edge types of the keypoints ``pos`` ``[*B, K, 2]``.

        Returns:
            ``edge_types`` ``[*B, K, K - 1, C]`` (receiver ``k``, then its senders in the order of
            :func:`~kinet_rl.models.interaction.edge_layout`; each a distribution over types) and
            ``kl`` ``[*B]``.
        """
        layout = edge_layout(pos.shape[-2], True, pos.device)
        nodes = self.node_encoder(pos)
        edges = self.edge_encoder(layout.pairs_of(edge_geometry(pos)))
        logits = layout.pair_mlp(self.edge_logits, nodes, edges)
        logits = 0.5 * (logits + layout.reversed(logits))  # undirected: (i, k) == (k, i)
        log_prob = logits.log_softmax(-1)
        kl = (log_prob.exp() * (log_prob + math.log(self.num_edge_types))).sum(-1)
        kl = kl.sum(dim=(-2, -1)) / layout.num_edges
        if self.training:
            return F.gumbel_softmax(logits, tau=GUMBEL_TEMPERATURE, dim=-1), kl
        return log_prob.exp(), kl


class EdgeTypeDynamics(nn.Module):
    """V-CDN's dynamics module on keypoint positions, conditioned on the push.

    ``n_k = f_node(x_k) + f_push(a_k)``: the node embedding of a keypoint's position plus an
    encoding of the push ``a_k = [u, s - x_k, e - x_k]`` (the push and its start and end relative
    to the keypoint; KINet's node update sees the same). Then ``L`` rounds of
    ``n_k += f_update(n_k, sum_i sum_{c >= 1} z^c_ik m^c_ik)`` with messages
    ``[m^1_ik, ..., m^{C-1}_ik] = f_msg(n_i, n_k, e_ik)`` (one per relation type; type 0 sends
    none) and ``x_hat_k = x_k + f_state(n_k)``.

    Reference: Li et al., NeurIPS 2020, Sec. 3.3; KINet, RA-L 2023, Sec. 5 (the push encoding
    added to each keypoint embedding).

    Args:
        num_edge_types: ``C`` of the edge types it is given.
        embed_dim: ``E`` of node, edge and message embeddings.
        hidden_dim: Hidden units of every MLP.
        num_hidden: Hidden layers of every MLP.
        num_rounds: ``L`` message-passing rounds.
    """

    def __init__(
        self,
        num_edge_types: int = 3,
        embed_dim: int = 64,
        hidden_dim: int = 128,
        num_hidden: int = 3,
        num_rounds: int = 3,
    ) -> None:
        super().__init__()
        check_edge_types(num_edge_types)
        if num_rounds < 1:
            raise ValueError(f"num_rounds must be >= 1, got {num_rounds}.")
        self.num_edge_types = num_edge_types
        self.num_rounds = num_rounds
        self.node_encoder = mlp(2, embed_dim, hidden_dim, num_hidden)
        self.push_encoder = mlp(PUSH_FEATURE_DIM, embed_dim, hidden_dim, num_hidden)
        self.edge_encoder = mlp(EDGE_GEOMETRY_DIM, embed_dim, hidden_dim, num_hidden)
        self.message = mlp(3 * embed_dim, (num_edge_types - 1) * embed_dim, hidden_dim, num_hidden)
        self.node_update = mlp(2 * embed_dim, embed_dim, hidden_dim, num_hidden)
        self.state_decoder = mlp(embed_dim, 2, hidden_dim, num_hidden)

    def forward(self, pos: Tensor, edge_types: Tensor, action: Tensor) -> Tensor:
        """Next keypoints ``[*B, K, 2]``.

        Args:
            pos: ``[*B, K, 2]`` keypoints ``x_t``.
            edge_types: ``[*B, K, K - 1, C]`` from :class:`EdgeTypeInference`.
            action: ``[*B, 4]`` push; the leading dims of all three broadcast.
        """
        batch = push_batch(pos, action)
        k = pos.shape[-2]
        if edge_types.shape[-3:] != (k, max(k - 1, 0), self.num_edge_types):
            raise ValueError(
                f"Expected edge_types [*B, {k}, {k - 1}, {self.num_edge_types}] for {k} keypoints, "
                f"got {tuple(edge_types.shape)}; infer them with EdgeTypeInference."
            )
        layout = edge_layout(k, True, pos.device)
        hidden = self.node_encoder(pos) + self.push_encoder(push_features(pos, action, batch))
        edges = self.edge_encoder(layout.pairs_of(edge_geometry(pos)))
        relations = edge_types[..., 1:].unsqueeze(-1)  # [*B, K, K - 1, C - 1, 1]: type 0 sends none
        for _ in range(self.num_rounds):
            messages = layout.pair_mlp(self.message, hidden, edges)
            messages = messages.unflatten(-1, (self.num_edge_types - 1, -1))
            aggregated = (relations * messages).sum(dim=(-3, -2))  # over senders and types
            hidden = hidden + self.node_update(torch.cat([hidden, aggregated], dim=-1))
        return pos + self.state_decoder(hidden)


class VCDNWorldModel(ConfigCheckpointMixin, KeypointWorldModel):
    """V-CDN baseline: frozen keypoint perception, inferred edge types, push-conditioned dynamics.

    The graph is inferred once from the keypoints where a prediction starts and kept over a
    rollout (V-CDN's causal graph is a property of the scene, not of a step). Train it with
    :class:`~kinet_rl.baselines.losses.VCDNLoss` (perception first, then frozen).

    Keys:
        :meth:`forward` reads ``ACTION`` ``[*B, 4]``, ``KP_POS`` ``[*B, K, 2]`` (or, if absent,
        ``PIXELS`` ``[*B, H, W, 3]``, then writes ``KP_POS``) and ``KP_EDGE_TYPE``
        ``[*B, K, K - 1, C]`` (inferred and written if absent); it writes the predictions
        ``("next", KP_POS)`` and ``("next", KP_EDGE_TYPE)`` (the graph carried over).

    Args:
        num_keypoints: ``K`` detected keypoints.
        channels: Detector/reconstructor conv width.
        blob_std: Gaussian blob std of the transport step, in ``[-1, 1]`` units.
        num_edge_types: ``C`` edge types, type 0 "no relation".
        embed_dim: ``E`` of node, edge and message embeddings.
        hidden_dim: Hidden units of every MLP.
        num_hidden: Hidden layers of every MLP.
        num_rounds: ``L`` message-passing rounds.
    """

    checkpoint_format = "kinet_rl.VCDNWorldModel/1"
    label = "V-CDN"
    capabilities = ModelCapabilities(
        observes=(PIXELS,),
        goal=(GOAL_PIXELS,),
        objectives=("keypoints_distance",),
        any_object_count=True,
        reconstructs=True,
        keypoints=True,
    )
    planning = PlanningDefaults("keypoints_distance")

    def __init__(
        self,
        num_keypoints: int = 6,
        channels: int = 32,
        blob_std: float = 0.1,
        num_edge_types: int = 3,
        embed_dim: int = 64,
        hidden_dim: int = 128,
        num_hidden: int = 3,
        num_rounds: int = 3,
    ) -> None:
        super().__init__()
        self.config: dict[str, Any] = {
            "num_keypoints": num_keypoints,
            "channels": channels,
            "blob_std": blob_std,
            "num_edge_types": num_edge_types,
            "embed_dim": embed_dim,
            "hidden_dim": hidden_dim,
            "num_hidden": num_hidden,
            "num_rounds": num_rounds,
        }
        self.detector = KeypointDetector(num_keypoints, feat_dim=0, channels=channels)
        self.reconstructor = KeypointReconstructor(channels, blob_std)
        self.inference = EdgeTypeInference(num_edge_types, embed_dim, hidden_dim, num_hidden)
        self.dynamics = EdgeTypeDynamics(
            num_edge_types, embed_dim, hidden_dim, num_hidden, num_rounds
        )

    def keypoints(self, pixels: Tensor) -> Tensor:
        """Detected keypoints ``[*B, K, 2]`` of images ``[*B, H, W, 3]``."""
        return self.detector(pixels)[0]

    def reconstruction_error(self, first: Tensor, current: Tensor) -> Tensor:
        """Mean squared error of rebuilding ``current`` from ``first`` through the keypoints.

        The perception stage's loss (KINet's ``loss_rec``): it trains detector and reconstructor
        from ``current``'s encoding (``first`` ``[B, H, W, 3]`` is encoded without gradient).
        """
        with torch.no_grad():
            source = self.detector.encode(first)
        observed = self.detector.encode(current)
        target = pixels_to_input(current).permute(0, 2, 3, 1)
        return (self.reconstructor(source, observed) - target).pow(2).mean()

    def roll(self, pos: Tensor, edge_types: Tensor, actions: Tensor) -> Tensor:
        """Keypoints ``[B, L, K, 2]`` after each push ``[B, L, 4]`` from ``pos`` ``[B, K, 2]``,
        with the graph ``edge_types`` kept."""
        steps = []
        for h in range(actions.shape[1]):
            pos = self.dynamics(pos, edge_types, actions[:, h])
            steps.append(pos)
        return torch.stack(steps, dim=1)

    def world_model(self, objective: str | None = None) -> PushWorldModel:
        """V-CDN as a ``torchrl.modules.WorldModel`` on its keypoints and inferred graph
        (:func:`~kinet_rl.baselines.imagination.vcdn_world_model`)."""
        name = check_objective(self.capabilities, objective or self.planning.objective, self.label)
        return vcdn_world_model(self, name)

    @torch.no_grad()
    def rollout_keypoints(self, pixels: Tensor, actions: Tensor) -> Tensor:
        """Detected keypoints of ``pixels`` ``[B, H, W, 3]`` and the predicted ones after each
        push ``[B, L, 4]``, the graph inferred at the start: ``[B, L + 1, K, 2]``."""
        pos = self.keypoints(pixels)
        edge_types, _ = self.inference(pos)
        return torch.cat([pos.unsqueeze(1), self.roll(pos, edge_types, actions)], dim=1)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Predicts the next keypoints for ``ACTION`` (see the class ``Keys:``)."""
        pos = tensordict.get(KP_POS, None)
        if pos is None:
            pixels = tensordict.get(PIXELS, None)
            if pixels is None:
                raise KeyError(
                    f"VCDNWorldModel needs {KP_POS!r} or {PIXELS!r} in the input; pass images or "
                    "detected keypoints."
                )
            pos = self.keypoints(pixels)
            tensordict.set(KP_POS, pos)
        edge_types = tensordict.get(KP_EDGE_TYPE, None)
        if edge_types is None:
            edge_types, _ = self.inference(pos)
            tensordict.set(KP_EDGE_TYPE, edge_types)
        tensordict.set(("next", *KP_POS), self.dynamics(pos, edge_types, tensordict.get(ACTION)))
        tensordict.set(("next", *KP_EDGE_TYPE), edge_types)
        return tensordict
