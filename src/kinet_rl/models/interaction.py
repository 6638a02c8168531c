"""Scene graph over keypoints and probabilistic message passing (``f_fwd``, ``f_state``).

Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 3.2-3.4.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from kinet_rl.planners.model_env import ACTION_DIM

#: Frames in which the push's points enter the node update (see :class:`KeypointInteractionNet`).
ACTION_FRAMES = ("table", "learned")


def mlp(in_dim: int, out_dim: int, hidden_dim: int = 128, num_hidden: int = 3) -> nn.Sequential:
    """MLP with ``num_hidden`` ReLU hidden layers of ``hidden_dim`` units and a linear output."""
    layers: list[nn.Module] = []
    dim = in_dim
    for _ in range(num_hidden):
        layers += [nn.Linear(dim, hidden_dim), nn.ReLU()]
        dim = hidden_dim
    layers.append(nn.Linear(dim, out_dim))
    return nn.Sequential(*layers)


def edge_geometry(pos: Tensor) -> Tensor:
    """Raw edge features ``e_ij = [x_i - x_j, |x_i - x_j|^2]``.

    Args:
        pos: ``[*B, K, 2]`` keypoints.

    Returns:
        ``[*B, K, K, 3]``; the diagonal (self-loops) is present but masked out downstream.
    """
    diff = pos.unsqueeze(-2) - pos.unsqueeze(-3)
    return torch.cat([diff, diff.pow(2).sum(-1, keepdim=True)], dim=-1)


def pairs(nodes: Tensor) -> tuple[Tensor, Tensor]:
    """Broadcasts ``[*B, K, D]`` node tensors to sender/receiver pairs ``[*B, K, K, D]`` (i, j)."""
    k = nodes.shape[-2]
    first = nodes.unsqueeze(-2).expand(*nodes.shape[:-1], k, nodes.shape[-1])
    second = nodes.unsqueeze(-3).expand(*nodes.shape[:-2], k, k, nodes.shape[-1])
    return first, second


def graph_similarity(nodes_a: Tensor, nodes_b: Tensor) -> Tensor:
    """Graph matching score ``S(G1, G2) = sum_k n1_k . n2_k``.

    Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 3.4 (contrastive loss, GraphMPC).

    Args:
        nodes_a: ``[*B, K, D]`` node embeddings.
        nodes_b: ``[*B, K, D]`` node embeddings (broadcastable).

    Returns:
        ``[*B]`` similarity.
    """
    if nodes_a.shape[-2:] != nodes_b.shape[-2:]:
        raise ValueError(
            f"Graphs must have the same [K, D]: got {tuple(nodes_a.shape)} and {tuple(nodes_b.shape)}."
        )
    return (nodes_a * nodes_b).sum(dim=(-2, -1))


def gaussian_kl_to_standard(mean: Tensor, log_std: Tensor) -> Tensor:
    """Elementwise ``KL(N(mean, std^2) || N(0, 1))``."""
    return 0.5 * (mean.pow(2) + torch.exp(2 * log_std) - 1) - log_std


@dataclass
class GraphPrediction:
    """Outputs of :class:`KeypointInteractionNet` for a batch of graphs.

    Attributes:
        next_pos: ``[*B, K, 2]`` predicted keypoints ``x_t + Delta x``.
        next_nodes: ``[*B, K, E]`` predicted node embeddings of ``G_{t+1}``.
        nodes: ``[*B, K, E]`` node embeddings of the input graph ``G_t``.
        edge_prob: ``[*B, K, K]`` edge weights ``z_ij`` used for aggregation (0 on the diagonal).
        kl: ``[*B]`` mean over edges of the KL between edge posterior and prior (0 if deterministic).
    """

    next_pos: Tensor
    next_nodes: Tensor
    nodes: Tensor
    edge_prob: Tensor
    kl: Tensor


class KeypointInteractionNet(nn.Module):
    """Action-conditioned probabilistic message passing over the keypoint scene graph.

    Node inputs are ``[phi_k, x_k]`` and edge inputs ``[x_i - x_j, |x_i - x_j|^2]`` (no
    self-loops); both are embedded to ``embed_dim``. Edges: the posterior over each undirected
    edge is a Gaussian over its logit, ``N(mu_ij, sigma_ij^2)`` from ``f_enc([n_i, n_j])``
    symmetrised over ``(i, j)``; in training a logit is sampled with the reparameterisation trick
    and ``z_ij = sigmoid(logit)``; in eval mode the mean logit is used. The inference loss is
    ``KL(N(mu, sigma^2) || N(0, 1))`` per edge (the independent Gaussian prior of the paper, put on
    the logit so that the prior over ``z`` is centred at 0.5). ``L`` rounds of
    ``e' = f_edge(n_i, n_j, e)``, ``e_bar_k = sum_{i != k} z_ik e'_ik``,
    ``n' = n + f_node(n, e_bar, a_k)`` follow, where ``a_k`` is the action ``u`` plus its start and
    end points relative to keypoint ``k`` (keeps the update translation-aware yet permutation
    equivariant). The push is in table coordinates and keypoints in image coordinates; with
    ``action_frame="learned"`` the push's points are first mapped into the image by a learnt
    affine map (initialised to the identity), which the top camera barely needs and an angled
    camera does. ``f_state`` maps the final node embedding to ``Delta x``. All functions are shared
    over keypoints, so the net works for any ``K`` and is permutation equivariant.

    Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 3.2-3.4.

    Args:
        feat_dim: ``D`` of the keypoint visual features.
        embed_dim: ``E`` of node and edge embeddings.
        hidden_dim: Hidden units of every MLP.
        num_hidden: Hidden layers of every MLP (paper: 3 of 128 units).
        num_rounds: ``L`` message-passing rounds.
        deterministic: Ablation: fully connected graph (``z = 1``) and no KL term.
        action_frame: ``"table"`` (the push's points are used as given) or ``"learned"`` (mapped
            into the image frame by a learnt affine map before the relative term).
    """

    def __init__(
        self,
        feat_dim: int = 16,
        embed_dim: int = 64,
        hidden_dim: int = 128,
        num_hidden: int = 3,
        num_rounds: int = 3,
        deterministic: bool = False,
        action_frame: str = "table",
    ) -> None:
        super().__init__()
        if num_rounds < 1:
            raise ValueError(f"num_rounds must be >= 1, got {num_rounds}.")
        if action_frame not in ACTION_FRAMES:
            raise ValueError(f"action_frame={action_frame!r}; choose one of {ACTION_FRAMES}.")
        self.action_to_image = None
        if action_frame == "learned":
            self.action_to_image = nn.Linear(2, 2)
            nn.init.eye_(self.action_to_image.weight)
            nn.init.zeros_(self.action_to_image.bias)
        self.feat_dim = feat_dim
        self.num_rounds = num_rounds
        self.deterministic = deterministic
        self.node_encoder = mlp(feat_dim + 2, embed_dim, hidden_dim, num_hidden)
        self.edge_encoder = mlp(3, embed_dim, hidden_dim, num_hidden)
        self.edge_posterior = (
            None if deterministic else mlp(2 * embed_dim, 2, hidden_dim, num_hidden)
        )
        self.edge_update = mlp(3 * embed_dim, embed_dim, hidden_dim, num_hidden)
        self.node_update = mlp(2 * embed_dim + 2 * ACTION_DIM, embed_dim, hidden_dim, num_hidden)
        self.state_decoder = mlp(embed_dim, 2, hidden_dim, num_hidden)

    def embed_nodes(self, pos: Tensor, feat: Tensor) -> Tensor:
        """Node embeddings ``n_k`` of the graph ``[phi_k, x_k]``: ``[*B, K, D], [*B, K, 2] -> [*B, K, E]``."""
        if (
            feat.shape[-1] != self.feat_dim
            or pos.shape[-1] != 2
            or pos.shape[:-1] != feat.shape[:-1]
        ):
            raise ValueError(
                f"Expected pos [*B, K, 2] and feat [*B, K, {self.feat_dim}], got "
                f"{tuple(pos.shape)} and {tuple(feat.shape)}."
            )
        return self.node_encoder(torch.cat([feat, pos], dim=-1))

    def _edge_prob(self, nodes: Tensor) -> tuple[Tensor, Tensor]:
        """Edge weights ``[*B, K, K]`` (diagonal 0) and per-graph mean KL ``[*B]``."""
        k = nodes.shape[-2]
        off_diag = ~torch.eye(k, dtype=torch.bool, device=nodes.device)
        if self.edge_posterior is None:
            return off_diag.to(nodes.dtype).expand(*nodes.shape[:-2], k, k), nodes.new_zeros(
                nodes.shape[:-2]
            )
        stats = self.edge_posterior(torch.cat(pairs(nodes), dim=-1))
        stats = 0.5 * (stats + stats.transpose(-2, -3))  # undirected: (i, j) == (j, i)
        mean, log_std = stats.unbind(-1)
        log_std = log_std.clamp(-6.0, 3.0)
        logit = mean
        if self.training:
            noise = torch.randn_like(mean)
            noise = (noise + noise.transpose(-1, -2)) / 2**0.5  # symmetric, unit variance off-diag
            logit = mean + noise * log_std.exp()
        prob = torch.sigmoid(logit) * off_diag
        num_edges = max(k * (k - 1), 1)
        kl = (gaussian_kl_to_standard(mean, log_std) * off_diag).sum(dim=(-2, -1)) / num_edges
        return prob, kl

    def forward(self, pos: Tensor, feat: Tensor, action: Tensor) -> GraphPrediction:
        """Predicts the next keypoints and graph.

        Args:
            pos: ``[*B, K, 2]`` keypoints ``x_t`` in ``[-1, 1]``.
            feat: ``[*B, K, D]`` keypoint features ``phi_t``.
            action: ``[*B, 4]`` push ``(start x, start y, end x, end y)``.

        Returns:
            :class:`GraphPrediction`.
        """
        if action.shape[-1] != ACTION_DIM or action.shape[:-1] != pos.shape[:-2]:
            raise ValueError(
                f"Expected action [*B, {ACTION_DIM}] matching pos [*B, K, 2]; got "
                f"{tuple(action.shape)} and {tuple(pos.shape)}."
            )
        nodes = self.embed_nodes(pos, feat)
        edges = self.edge_encoder(edge_geometry(pos))
        prob, kl = self._edge_prob(nodes)
        # [*B, K, 2, 2]: push start and end relative to each keypoint
        points = action.reshape(*action.shape[:-1], 1, 2, 2)
        if self.action_to_image is not None:
            points = self.action_to_image(points)
        action_rel = points - pos.unsqueeze(-2)
        action_in = torch.cat(
            [action.unsqueeze(-2).expand(*pos.shape[:-1], ACTION_DIM), action_rel.flatten(-2)], -1
        )
        hidden = nodes
        for _ in range(self.num_rounds):
            first, second = pairs(hidden)
            edges = self.edge_update(torch.cat([first, second, edges], dim=-1))
            aggregated = (prob.unsqueeze(-1) * edges).sum(dim=-3)  # sum over senders i of e'_ik
            hidden = hidden + self.node_update(torch.cat([hidden, aggregated, action_in], dim=-1))
        return GraphPrediction(
            next_pos=pos + self.state_decoder(hidden),
            next_nodes=hidden,
            nodes=nodes,
            edge_prob=prob,
            kl=kl,
        )
