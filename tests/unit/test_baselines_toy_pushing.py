"""Tests of the synthetic pushing data used to test the baselines."""

from __future__ import annotations

import torch

from toy_pushing import ToyPushData, push_objects


def test_push_moves_only_objects_on_the_push_line():
    pos = torch.tensor([[[0.05, 0.0], [0.05, 0.2], [-0.1, 0.0]]])  # ahead, aside, behind
    moved = push_objects(
        pos, torch.tensor([[0.0, 0.0]]), torch.tensor([[0.1, 0.0]]), half_size=0.02
    )
    # the pushed centre ends half a side past the push end
    assert torch.allclose(moved[0, 0], torch.tensor([0.12, 0.0]))
    assert torch.equal(moved[0, 1:], pos[0, 1:])


def test_data_is_seeded_and_matches_the_dataset_api():
    a, b = (
        ToyPushData(num_episodes=4, episode_length=3, seed=5),
        ToyPushData(num_episodes=4, episode_length=3, seed=5),
    )
    assert torch.equal(a.pixels, b.pixels) and torch.equal(a.action, b.action)
    assert a.action.abs().max() <= 1.0
    td = a.sample(6, torch.Generator().manual_seed(0))
    assert td["pixels"].shape == (6, 32, 32, 3) and td["pixels"].dtype == torch.uint8
    assert td[("next", "object_pos")].shape == (6, 3, 2) and td["action"].shape == (6, 4)
    assert torch.equal(td[("next", "pixels")], a.pixels[td["episode"], td["step"] + 1])
    seq = a.sample_sequences(5, 2, torch.Generator().manual_seed(0))
    assert seq["pixels"].shape == (5, 3, 32, 32, 3) and seq["action"].shape == (5, 2, 4)
    assert torch.equal(seq["object_pos"][:, 0], a.object_pos[seq["episode"], seq["step"]])
