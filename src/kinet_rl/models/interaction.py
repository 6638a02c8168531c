"""Scene graph over keypoints and probabilistic message passing (``f_fwd``, ``f_state``).

Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 3.2-3.4.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from kinet_rl.planners.world_model import ACTION_DIM

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
        ``[*B, K, K, 3]``, entry ``[i, j]`` for the edge from ``i`` to ``j`` (diagonal: self-loops).
    """
    diff = pos.unsqueeze(-2) - pos.unsqueeze(-3)
    return torch.cat([diff, diff.pow(2).sum(-1, keepdim=True)], dim=-1)


def concat(parts: Sequence[Tensor]) -> Tensor:
    """``cat(parts, -1)`` after broadcasting the parts' leading dims against each other."""
    shape = torch.broadcast_shapes(*(part.shape[:-1] for part in parts))
    return torch.cat([part.expand(*shape, part.shape[-1]) for part in parts], dim=-1)


def add_linear(acc: Tensor, x: Tensor, weight: Tensor) -> Tensor:
    """``acc + x W^T`` (leading dims broadcast), one ``addmm`` when they are the same."""
    if acc.shape[:-1] != x.shape[:-1]:
        return acc + F.linear(x, weight)
    flat = torch.addmm(acc.reshape(-1, acc.shape[-1]), x.reshape(-1, x.shape[-1]), weight.t())
    return flat.view(acc.shape)


def mlp_of_parts(net: nn.Sequential, parts: Sequence[Tensor], split: bool) -> Tensor:
    """``net(concat(parts))``; with ``split``, its first layer is applied part by part.

    The first layer is ``W concat(parts) + b = sum_p W_p x_p + b``. With ``split`` each term is
    computed at its part's own shape, so a part shared by many rows (a start state by all
    candidates) is multiplied once, and the terms broadcast-sum.

    Args:
        net: An :func:`mlp`.
        parts: Inputs ``[*B_p, D_p]`` whose leading dims broadcast.
        split: Split the first layer instead of one matmul over the broadcast concatenation.
    """
    if not split:
        return net(concat(parts))
    layer = _first_layer(net)
    weights = layer.weight.split([part.shape[-1] for part in parts], dim=-1)
    hidden = F.linear(parts[0], weights[0], layer.bias)
    for part, weight in zip(parts[1:], weights[1:], strict=True):
        hidden = add_linear(hidden, part, weight)
    return _after_first_layer(net, hidden)


def _first_layer(net: nn.Sequential) -> nn.Linear:
    layer = net[0]
    if not isinstance(layer, nn.Linear):
        raise TypeError(f"Expected an mlp() starting with nn.Linear, got {type(layer).__name__}.")
    return layer


def _after_first_layer(net: nn.Sequential, hidden: Tensor) -> Tensor:
    """The layers of ``net`` after the first on its pre-activation ``hidden``.

    ReLUs run in place: ``hidden`` and every layer output are fresh tensors of this computation.
    """
    for layer in list(net)[1:]:
        hidden = torch.relu_(hidden) if isinstance(layer, nn.ReLU) else layer(hidden)
    return hidden


@dataclass(frozen=True, eq=False)
class EdgeLayout:
    """Where the directed edges ``(sender i, receiver k)`` of a ``K``-node graph are stored.

    Edge tensors are ``[*B, K, P, *F]``: receiver ``k``, then its ``P`` senders ``senders[k]``,
    so that a node's incoming messages are a sum over one dim. The fast layout holds the
    ``K (K - 1)`` edges without self-loops and multiplies the pair MLPs' per-node inputs by their
    first-layer weights once per node, not once per edge; the straightforward one holds
    all ``K^2`` pairs (self-loops masked out) and runs the pair MLPs on concatenations. Both
    compute the same function (``fast`` of :meth:`KeypointInteractionNet.forward`).

    Attributes:
        fast: Which of the two layouts this is.
        senders: ``[K, P]`` sender of each stored edge.
        matrix_index: ``[K, P]`` flat index ``i * K + k`` of each edge in a ``[K, K]`` matrix.
        reverse: ``[K, P]`` flat index (into ``K * P``) of each edge's reverse ``(k, i)``.
        mask: ``[K, P]`` 0 on self-loops, 1 elsewhere; None when no self-loop is stored.
    """

    fast: bool
    senders: Tensor
    matrix_index: Tensor
    reverse: Tensor
    mask: Tensor | None

    @property
    def num_edges(self) -> int:
        """Number of edges without self-loops, ``K (K - 1)`` (at least 1, as a divisor)."""
        k = self.senders.shape[0]
        return max(k * (k - 1), 1)

    def pairs_of(self, matrix: Tensor) -> Tensor:
        """Entries ``[i, k]`` of ``[*B, K, K, F]`` matrices, in this layout: ``[*B, K, P, F]``."""
        return _gather_rows(matrix.flatten(-3, -2), self.matrix_index)

    def to_matrix(self, values: Tensor) -> Tensor:
        """``[*B, K, P]`` edge values as ``[*B, K, K]`` matrices (entry ``[i, k]``), 0 elsewhere."""
        k = self.senders.shape[0]
        flat = values.new_zeros(*values.shape[:-2], k * k)
        flat = flat.index_copy(-1, self.matrix_index.flatten(), values.flatten(-2))
        return flat.unflatten(-1, (k, k))

    def reversed(self, values: Tensor) -> Tensor:
        """Each edge's value ``[*B, K, P, F]`` replaced by that of its reverse edge."""
        return _gather_rows(values.flatten(-3, -2), self.reverse)

    def pair_mlp(self, net: nn.Sequential, nodes: Tensor, edges: Tensor | None = None) -> Tensor:
        """``net([n_i, n_k(, e_ik)])`` on every stored edge: ``[*B, K, P, out]``.

        Args:
            net: An :func:`mlp` over ``2 E (+ E')`` inputs.
            nodes: ``[*B, K, E]`` node embeddings.
            edges: Optional ``[*B', K, P, E']`` edge embeddings (leading dims broadcast).
        """
        if not self.fast:
            parts = [nodes[..., self.senders, :], nodes.unsqueeze(-2)]
            return net(concat(parts if edges is None else [*parts, edges]))
        # the first layer W [n_i, n_k, e_ik] + b = (W_s n + b)_i + (W_r n)_k + W_e e_ik
        layer = _first_layer(net)
        e = nodes.shape[-1]
        sender, receiver, edge = layer.weight.split([e, e, layer.in_features - 2 * e], dim=-1)
        hidden = _gather_rows(F.linear(nodes, sender, layer.bias), self.senders)  # [*B, K, P, H]
        hidden += F.linear(nodes, receiver).unsqueeze(-2)
        if edges is not None:
            hidden = add_linear(hidden, edges, edge)
        return _after_first_layer(net, hidden)


def _gather_rows(values: Tensor, index: Tensor) -> Tensor:
    """``values[..., index, :]``: the rows of ``[*B, M, F]`` at ``index`` ``[K, P]``."""
    return values.index_select(-2, index.flatten()).unflatten(-2, index.shape)


def edge_layout(num_nodes: int, fast: bool, device: torch.device) -> EdgeLayout:
    """The :class:`EdgeLayout` of ``num_nodes`` nodes (fast: without self-loops) on ``device``.

    Cached per arguments; under ``torch.compile`` its construction is traced into the graph
    instead (dynamo does not honour the cache).
    """
    if torch.compiler.is_compiling():
        return _build_edge_layout(num_nodes, fast, device)
    return _cached_edge_layout(num_nodes, fast, device)


def _build_edge_layout(num_nodes: int, fast: bool, device: torch.device) -> EdgeLayout:
    k = num_nodes
    everyone = torch.arange(k, device=device)
    receivers = everyone.unsqueeze(-1)  # [K, 1]
    if fast:
        # receiver k's senders are 0, ..., k - 1, k + 1, ..., K - 1; computed without boolean-mask
        # indexing, whose data-dependent shape would break a torch.compile graph
        slots = torch.arange(k - 1, device=device)
        senders = slots + (slots >= receivers).long()  # [K, K - 1]
    else:
        senders = everyone.expand(k, k)  # [K, K]: every node sends to every node
    receivers = receivers.expand_as(senders)
    slot = torch.full((k, k), -1, dtype=torch.long, device=device)  # [receiver, sender] -> slot
    slot[receivers, senders] = torch.arange(senders.shape[1], device=device).expand_as(senders)
    reverse = senders * senders.shape[1] + slot[senders, receivers]
    mask = None if fast else (senders != receivers).float()
    return EdgeLayout(fast, senders, senders * k + receivers, reverse, mask)


_cached_edge_layout = functools.lru_cache(maxsize=64)(_build_edge_layout)


#: Size of :func:`push_features`: the push and its two points relative to a node.
PUSH_FEATURE_DIM = 2 * ACTION_DIM


def push_batch(pos: Tensor, action: Tensor) -> torch.Size:
    """The broadcast batch dims of graphs ``pos`` ``[*B, K, 2]`` and pushes ``action`` ``[*B, 4]``.

    Raises:
        ValueError: The action is not 4-d or the leading dims do not broadcast.
    """
    try:
        batch = torch.broadcast_shapes(pos.shape[:-2], action.shape[:-1])
    except RuntimeError:
        batch = None
    if action.shape[-1] != ACTION_DIM or batch is None:
        raise ValueError(
            f"Expected action [*B, {ACTION_DIM}] matching pos [*B, K, 2]; got "
            f"{tuple(action.shape)} and {tuple(pos.shape)}."
        )
    return batch


def push_features(
    pos: Tensor, action: Tensor, batch: torch.Size, to_image: nn.Module | None = None
) -> Tensor:
    """Each node's push input ``a_k = [u, s - x_k, e - x_k]``: ``[*B, K, PUSH_FEATURE_DIM]``.

    ``s`` and ``e`` are the push's start and end points (mapped by ``to_image`` if given), so
    the input says where the push passes relative to the node, whatever the node's position.

    Args:
        pos: ``[*B, K, 2]`` node positions.
        action: ``[*B, 4]`` push ``(start x, start y, end x, end y)``.
        batch: The broadcast of ``pos``'s and ``action``'s leading dims.
        to_image: Optional map of the push's points into the nodes' frame.
    """
    points = action.reshape(*action.shape[:-1], 1, 2, 2)  # [*B, 1, 2 points, 2]
    if to_image is not None:
        points = to_image(points)
    relative = (points - pos.unsqueeze(-2)).flatten(-2)  # [*B, K, 4]
    k = pos.shape[-2]
    return torch.cat(
        [action.unsqueeze(-2).expand(*batch, k, ACTION_DIM), relative.expand(*batch, k, -1)], -1
    )


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
        self.embed_dim = embed_dim
        self.num_rounds = num_rounds
        self.deterministic = deterministic
        self.node_encoder = mlp(feat_dim + 2, embed_dim, hidden_dim, num_hidden)
        self.edge_encoder = mlp(3, embed_dim, hidden_dim, num_hidden)
        self.edge_posterior = (
            None if deterministic else mlp(2 * embed_dim, 2, hidden_dim, num_hidden)
        )
        self.edge_update = mlp(3 * embed_dim, embed_dim, hidden_dim, num_hidden)
        self.node_update = mlp(2 * embed_dim + PUSH_FEATURE_DIM, embed_dim, hidden_dim, num_hidden)
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

    def _edge_prob(
        self, nodes: Tensor, layout: EdgeLayout, batch: torch.Size
    ) -> tuple[Tensor, Tensor]:
        """Edge weights ``[*B, K, P]`` (0 on self-loops) and per-graph mean KL ``[*B]``.

        ``nodes`` ``[*S, K, E]`` may have fewer or size-1 leading dims than ``batch``: the
        posterior is computed at the nodes' shape, the sampling noise (training) at ``batch``;
        both outputs are returned at the smallest shape that broadcasts to ``batch``.
        """
        k = nodes.shape[-2]
        if self.edge_posterior is None:
            prob = nodes.new_ones(k, layout.senders.shape[1])
            return prob if layout.mask is None else layout.mask.to(prob), nodes.new_zeros(())
        stats = layout.pair_mlp(self.edge_posterior, nodes)
        stats = 0.5 * (stats + layout.reversed(stats))  # undirected: (i, j) == (j, i)
        mean, log_std = stats.unbind(-1)
        log_std = log_std.clamp(-6.0, 3.0)
        logit = mean
        if self.training:
            noise = torch.randn((*batch, k, k), dtype=mean.dtype, device=mean.device)
            noise = (noise + noise.transpose(-1, -2)) / 2**0.5  # symmetric, unit variance off-diag
            logit = mean + layout.pairs_of(noise.unsqueeze(-1)).squeeze(-1) * log_std.exp()
        prob = torch.sigmoid(logit)
        kl = gaussian_kl_to_standard(mean, log_std)
        if layout.mask is not None:
            prob, kl = prob * layout.mask, kl * layout.mask
        return prob, kl.sum(dim=(-2, -1)) / layout.num_edges

    def forward(
        self, pos: Tensor, feat: Tensor, action: Tensor, fast: bool = True
    ) -> GraphPrediction:
        """Predicts the next keypoints and graph.

        The graph's leading dims may broadcast against the action's: one start graph
        ``[*B, 1, K, .]`` with candidate pushes ``[*B, N, 4]`` computes what does not depend on
        the push (node and edge encodings, edge posterior, first edge update) once and broadcasts
        it over the candidates.

        Args:
            pos: ``[*B, K, 2]`` keypoints ``x_t`` in ``[-1, 1]``.
            feat: ``[*B, K, D]`` keypoint features ``phi_t``.
            action: ``[*B, 4]`` push ``(start x, start y, end x, end y)``.
            fast: Edges without self-loops and pair MLPs split per node (see
                :class:`EdgeLayout`); False runs the straightforward computation (all ``K^2``
                pairs, every MLP on a concatenation), the same function with more arithmetic.

        Returns:
            :class:`GraphPrediction` with the broadcast batch dims.
        """
        batch = push_batch(pos, action)
        k = pos.shape[-2]
        layout = edge_layout(k, fast, pos.device)
        nodes = self.embed_nodes(pos, feat)
        edges = self.edge_encoder(layout.pairs_of(edge_geometry(pos)))
        prob, kl = self._edge_prob(nodes, layout, batch)
        action_in = push_features(pos, action, batch, self.action_to_image)
        hidden = nodes
        for _ in range(self.num_rounds):
            edges = layout.pair_mlp(self.edge_update, hidden, edges)
            aggregated = (prob.unsqueeze(-1) * edges).sum(dim=-2)  # sum over senders i of e'_ik
            update = mlp_of_parts(self.node_update, [hidden, aggregated, action_in], split=fast)
            hidden = hidden + update
        return GraphPrediction(
            next_pos=pos + self.state_decoder(hidden),
            next_nodes=hidden,
            nodes=nodes.expand(*batch, *nodes.shape[-2:]),
            edge_prob=layout.to_matrix(prob).expand(*batch, k, k),
            kl=kl.expand(batch),
        )
