"""Scene graph and probabilistic message passing: equivariance, edges, any K, KL, ablation."""

from __future__ import annotations

import math

import pytest
import torch

from kinet_rl.models.interaction import (
    KeypointInteractionNet,
    edge_geometry,
    edge_layout,
    gaussian_kl_to_standard,
    graph_similarity,
)

FEAT_DIM = 4


def make_net(deterministic: bool = False) -> KeypointInteractionNet:
    torch.manual_seed(0)
    return KeypointInteractionNet(
        feat_dim=FEAT_DIM,
        embed_dim=8,
        hidden_dim=16,
        num_hidden=1,
        num_rounds=2,
        deterministic=deterministic,
    )


def graph_inputs(batch: int = 2, k: int = 5) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    gen = torch.Generator().manual_seed(1)
    pos = torch.rand(batch, k, 2, generator=gen) * 2 - 1
    feat = torch.randn(batch, k, FEAT_DIM, generator=gen)
    action = torch.rand(batch, 4, generator=gen) * 2 - 1
    return pos, feat, action


def test_prediction_shapes_dtypes_and_diagonal():
    net = make_net()
    pos, feat, action = graph_inputs(batch=3, k=5)
    out = net(pos, feat, action)
    assert out.next_pos.shape == (3, 5, 2) and out.next_pos.dtype == torch.float32
    assert out.next_nodes.shape == out.nodes.shape == (3, 5, 8)
    assert out.edge_prob.shape == (3, 5, 5) and out.kl.shape == (3,)
    assert torch.all(out.edge_prob.diagonal(dim1=-2, dim2=-1) == 0)  # no self-loops
    assert torch.all((out.edge_prob >= 0) & (out.edge_prob <= 1))
    torch.testing.assert_close(out.edge_prob, out.edge_prob.transpose(-1, -2))  # undirected


def test_edge_geometry_is_difference_and_squared_distance():
    pos = torch.tensor([[0.0, 0.0], [0.3, -0.4]])
    edges = edge_geometry(pos)
    torch.testing.assert_close(edges[0, 1], torch.tensor([-0.3, 0.4, 0.25]))
    torch.testing.assert_close(edges[1, 0], torch.tensor([0.3, -0.4, 0.25]))
    assert torch.all(edges.diagonal(dim1=0, dim2=1) == 0)


@pytest.mark.parametrize("deterministic", [False, True])
def test_permutation_equivariance_over_keypoints(deterministic):
    net = make_net(deterministic).eval()
    pos, feat, action = graph_inputs(batch=2, k=5)
    perm = torch.tensor([3, 0, 4, 1, 2])
    out = net(pos, feat, action)
    out_perm = net(pos[:, perm], feat[:, perm], action)
    torch.testing.assert_close(out_perm.next_pos, out.next_pos[:, perm])
    torch.testing.assert_close(out_perm.next_nodes, out.next_nodes[:, perm])
    torch.testing.assert_close(out_perm.edge_prob, out.edge_prob[:, perm][:, :, perm])
    torch.testing.assert_close(out_perm.kl, out.kl)


def test_each_round_updates_the_edge_features_it_passes_on():
    net = make_net().eval()
    calls: list[tuple[torch.Tensor, torch.Tensor]] = []
    net.edge_update.register_forward_hook(lambda m, inp, out: calls.append((inp[0], out)))
    net(*graph_inputs(), fast=False)  # the straightforward path calls f_edge on [n_i, n_j, e]
    assert len(calls) == net.num_rounds
    embed = calls[0][1].shape[-1]
    for (inp, out), (next_inp, _) in zip(calls, calls[1:], strict=False):
        edges_in, edges_next_round = inp[..., -embed:], next_inp[..., -embed:]
        torch.testing.assert_close(edges_next_round, out)  # round l+1 sees round l's edges
        assert (out - edges_in).abs().mean() > 1e-3  # and they differ from round l's input


def test_messages_depend_on_other_keypoints():
    net = make_net().eval()
    pos, feat, action = graph_inputs(batch=1, k=3)
    moved = pos.clone()
    moved[0, 2] += 0.5  # only keypoint 2 moves
    delta_0 = net(pos, feat, action).next_pos[0, 0] - pos[0, 0]
    delta_0_moved = net(moved, feat, action).next_pos[0, 0] - moved[0, 0]
    assert (delta_0 - delta_0_moved).abs().max() > 1e-4


@pytest.mark.parametrize("k", [1, 2, 9])
def test_any_number_of_keypoints_works(k):
    net = make_net().eval()
    pos, feat, action = graph_inputs(batch=2, k=k)
    out = net(pos, feat, action)
    assert out.next_pos.shape == (2, k, 2)
    assert torch.isfinite(out.next_pos).all() and torch.isfinite(out.kl).all()


def test_arbitrary_batch_dims():
    net = make_net().eval()
    pos, feat, action = graph_inputs(batch=6, k=3)
    flat = net(pos, feat, action).next_pos
    nested = net(pos.reshape(2, 3, 3, 2), feat.reshape(2, 3, 3, FEAT_DIM), action.reshape(2, 3, 4))
    torch.testing.assert_close(nested.next_pos.reshape(6, 3, 2), flat)


def test_kl_is_zero_at_the_prior_and_grows_away_from_it():
    zero = torch.zeros(3)
    torch.testing.assert_close(gaussian_kl_to_standard(zero, zero), zero)
    kls = [gaussian_kl_to_standard(torch.tensor(m), torch.tensor(s)) for m, s in [(0.5, 0), (2, 0)]]
    assert 0 < kls[0] < kls[1]
    assert gaussian_kl_to_standard(torch.tensor(0.0), torch.tensor(-1.0)) > 0  # too narrow


def test_net_kl_matches_posterior_set_to_prior_or_away_from_it():
    net = make_net()
    head = net.edge_posterior[-1]
    pos, feat, action = graph_inputs()
    with torch.no_grad():
        head.weight.zero_()
        head.bias.zero_()  # posterior N(0, 1) == prior
        kl_prior = net(pos, feat, action).kl
        head.bias.copy_(torch.tensor([2.0, -1.0]))  # mean 2, std e^-1
        kl_away = net(pos, feat, action).kl
    torch.testing.assert_close(kl_prior, torch.zeros(2))
    expected = 0.5 * (4 + math.exp(-2) - 1) + 1
    torch.testing.assert_close(kl_away, torch.full((2,), expected))


def test_training_samples_edges_and_eval_uses_the_mean():
    net = make_net()
    pos, feat, action = graph_inputs()
    torch.manual_seed(3)
    train_a, train_b = net(pos, feat, action).edge_prob, net(pos, feat, action).edge_prob
    net.eval()
    eval_a, eval_b = net(pos, feat, action).edge_prob, net(pos, feat, action).edge_prob
    assert not torch.allclose(train_a, train_b)
    torch.testing.assert_close(eval_a, eval_b)


def test_deterministic_ablation_is_fully_connected_without_kl():
    net = make_net(deterministic=True)
    assert net.edge_posterior is None
    out = net(*graph_inputs(batch=2, k=4))
    torch.testing.assert_close(out.edge_prob, (1 - torch.eye(4)).expand(2, 4, 4))
    torch.testing.assert_close(out.kl, torch.zeros(2))


def test_graph_similarity_sums_node_dot_products():
    a = torch.tensor([[[1.0, 2.0], [0.0, 1.0]]])
    b = torch.tensor([[[3.0, 0.5], [2.0, -1.0]]])
    torch.testing.assert_close(graph_similarity(a, b), torch.tensor([3.0 + 1.0 - 1.0]))
    with pytest.raises(ValueError, match="same \\[K, D\\]"):
        graph_similarity(a, torch.zeros(1, 3, 2))


@pytest.mark.parametrize(
    ("pos_shape", "feat_shape", "action_shape", "match"),
    [
        ((2, 3, 2), (2, 3, FEAT_DIM + 1), (2, 4), "feat"),
        ((2, 3, 3), (2, 3, FEAT_DIM), (2, 4), "pos"),
        ((2, 3, 2), (2, 3, FEAT_DIM), (2, 2), "action"),
        ((2, 3, 2), (2, 3, FEAT_DIM), (3, 4), "action"),
    ],
)
def test_bad_shapes_are_named(pos_shape, feat_shape, action_shape, match):
    net = make_net()
    with pytest.raises(ValueError, match=match):
        net(torch.zeros(pos_shape), torch.zeros(feat_shape), torch.zeros(action_shape))


def test_rejects_zero_rounds():
    with pytest.raises(ValueError, match="num_rounds"):
        KeypointInteractionNet(num_rounds=0)


def test_a_learned_action_frame_starts_as_the_table_frame_and_learns():
    torch.manual_seed(0)
    table = KeypointInteractionNet(feat_dim=4, embed_dim=8, hidden_dim=16, num_hidden=1)
    torch.manual_seed(0)
    learned = KeypointInteractionNet(
        feat_dim=4, embed_dim=8, hidden_dim=16, num_hidden=1, action_frame="learned"
    )
    learned.load_state_dict(table.state_dict(), strict=False)
    table.eval(), learned.eval()
    pos, feat, action = torch.rand(2, 3, 2), torch.rand(2, 3, 4), torch.rand(2, 4)
    assert torch.allclose(learned(pos, feat, action).next_pos, table(pos, feat, action).next_pos)
    learned(pos, feat, action).next_pos.sum().backward()
    assert learned.action_to_image.weight.grad.abs().sum() > 0
    with pytest.raises(ValueError, match="action_frame='image'"):
        KeypointInteractionNet(action_frame="image")


@pytest.mark.parametrize("k", [1, 2, 3, 6])
def test_edge_layouts_store_each_directed_edge_once(k: int) -> None:
    cpu = torch.device("cpu")
    fast, full = edge_layout(k, True, cpu), edge_layout(k, False, cpu)
    for receiver in range(k):  # the fast layout: every other node, in order; the full one: all
        assert fast.senders[receiver].tolist() == [i for i in range(k) if i != receiver]
        assert full.senders[receiver].tolist() == list(range(k))
    assert fast.mask is None and full.mask is not None
    assert torch.equal(full.mask, 1 - torch.eye(k))
    for layout in (fast, full):
        senders = layout.senders.flatten()
        receivers = torch.arange(k).repeat_interleave(layout.senders.shape[1])
        assert torch.equal(layout.matrix_index.flatten(), senders * k + receivers)
        # an edge's reverse runs from its receiver to its sender
        assert torch.equal(senders[layout.reverse.flatten()], receivers)
        assert torch.equal(receivers[layout.reverse.flatten()], senders)
