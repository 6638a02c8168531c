"""The contrastive term: same-episode negatives and bounded logits (KINet Sec. 3.5)."""

from __future__ import annotations

import math

import pytest
import torch
from tensordict import TensorDict

from kinet_rl.data.dataset import sample_steps
from kinet_rl.keys import ACTION, EPISODE, PIXELS, PIXELS_0
from kinet_rl.models import KINetLoss, KINetWorldModel, graph_info_nce
from kinet_rl.models.losses import graph_logits


def graphs(n: int, seed: int) -> torch.Tensor:
    return torch.randn(n, 3, 4, generator=torch.Generator().manual_seed(seed))


def test_episode_negatives_are_only_other_steps_of_the_same_episode():
    # Episode 0 holds samples 0 and 1, episode 1 samples 2 and 3. The target of sample 2 equals
    # sample 0's prediction: a batch negative that would confuse sample 0, but it is from another
    # episode, so the episode loss ignores it.
    target = graphs(4, 0)
    predicted = target.clone()
    target[2] = predicted[0]
    groups = torch.tensor([0, 0, 1, 1])
    batch_loss = graph_info_nce(predicted, target, 0.1, "cosine")
    episode_loss = graph_info_nce(predicted, target, 0.1, "cosine", groups)
    assert episode_loss < 0.05 < batch_loss


def test_a_sample_alone_in_its_episode_has_no_negatives_and_is_left_out():
    predicted, target = graphs(3, 1), graphs(3, 2)
    loss = graph_info_nce(predicted, target, groups=torch.tensor([0, 1, 2]))
    assert loss == 0
    pair = graph_info_nce(predicted[:2], target[:2], groups=torch.tensor([5, 5]))
    both = graph_info_nce(predicted, target, groups=torch.tensor([5, 5, 9]))
    assert torch.isclose(both, pair)


def test_bounded_logits_do_not_grow_with_the_embedding_norm():
    a, b = graphs(4, 3), graphs(4, 4)
    for similarity in ("cosine",):
        assert torch.allclose(graph_logits(10 * a, b, similarity), graph_logits(a, b, similarity))
    dot = graph_logits(a, a, "dot")
    assert torch.allclose(graph_logits(10 * a, a, "dot"), 10 * dot)
    distance = graph_logits(a, b, "distance")
    assert (distance <= 0).all() and torch.allclose(
        graph_logits(a, a, "distance").diag(), torch.zeros(4)
    )
    assert graph_logits(a, a, "cosine").diag().allclose(torch.ones(4))


def test_grouped_sampling_draws_distinct_steps_of_each_episode():
    gen = torch.Generator().manual_seed(0)
    episode, step = sample_steps(50, 20, 32, steps_per_episode=4, generator=gen)
    assert episode.shape == step.shape == (32,)
    for group in range(8):
        rows = slice(4 * group, 4 * group + 4)
        assert episode[rows].unique().numel() == 1
        assert step[rows].unique().numel() == 4
    with pytest.raises(ValueError, match="must divide batch_size"):
        sample_steps(50, 20, 30, steps_per_episode=4)


def test_uniform_sampling_is_unchanged_by_the_grouping_option():
    a = sample_steps(50, 20, 16, 1, torch.Generator().manual_seed(3))
    gen = torch.Generator().manual_seed(3)
    b = (torch.randint(50, (16,), generator=gen), torch.randint(20, (16,), generator=gen))
    assert all(torch.equal(x, y) for x, y in zip(a, b, strict=True))


def transitions(size: int, episodes: torch.Tensor | None) -> TensorDict:
    gen = torch.Generator().manual_seed(0)
    frames = torch.randint(0, 256, (3, size, 16, 16, 3), dtype=torch.uint8, generator=gen)
    td = TensorDict(
        {
            PIXELS_0: frames[0],
            PIXELS: frames[1],
            ACTION: torch.rand(size, 4, generator=gen) * 2 - 1,
        },
        batch_size=[size],
    )
    td["next", PIXELS] = frames[2]
    if episodes is not None:
        td[EPISODE] = episodes
    return td


def tiny_model() -> KINetWorldModel:
    torch.manual_seed(0)
    return KINetWorldModel(
        num_keypoints=3, feat_dim=4, channels=8, embed_dim=8, hidden_dim=16, num_hidden=1
    )


def test_the_loss_uses_the_episode_of_each_transition():
    loss = KINetLoss(tiny_model(), ctr_weight=1.0, ctr_negatives="episode", ctr_similarity="cosine")
    alone = loss(transitions(4, torch.tensor([0, 1, 2, 3])))["loss_ctr"]
    paired = loss(transitions(4, torch.tensor([0, 0, 1, 1])))["loss_ctr"]
    assert alone == 0
    assert 0 < paired.item() < 2 * math.log(2) + 1  # two candidates per sample, bounded logits
    with pytest.raises(KeyError, match="needs the 'episode'"):
        loss(transitions(4, None))
