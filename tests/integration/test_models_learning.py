"""KINet learns on tiny synthetic pushes: losses fall and predictions beat the no-motion baseline.

Data: 32x32 images of a red and a blue square on grey; each push picks a square, starts just
behind it and ends where the square ends up (it moves to the push end). No MuJoCo needed.
Thresholds were set from seeds 0, 1 and 2 at 600 steps (about 50 s on a busy 2-core CPU):
``loss_rec`` on held-out transitions fell 44-119x (>= 10 asserted); on the trained detector's
keypoints the trained interaction net's forward loss was 3.7-9.6x below the untrained net's
(>= 2 asserted) and 0.12-0.28 of the no-motion error (< 0.5 asserted).
"""

from __future__ import annotations

import copy
import math

import pytest
import torch
from tensordict import TensorDict

from kinet_rl.keys import ACTION, PIXELS, PIXELS_0
from kinet_rl.models import KINetLoss, KINetWorldModel

pytestmark = pytest.mark.slow

SIZE = 32
HALF_SIDE = 3  # squares of 6x6 pixels
COLOURS = torch.tensor([[0.9, 0.15, 0.15], [0.15, 0.3, 0.9]])
PUSHES = 4
SEED = 0
STEPS = 600
BATCH = 16


def render(pos: torch.Tensor) -> torch.Tensor:
    """Float ``[H, W, 3]`` image of squares centred at ``pos`` ``[N, 2]`` in ``[-1, 1]``."""
    image = torch.full((SIZE, SIZE, 3), 0.5)
    for colour, (x, y) in zip(COLOURS, ((pos + 1) / 2 * SIZE).round().long(), strict=True):
        image[max(y - HALF_SIDE, 0) : y + HALF_SIDE, max(x - HALF_SIDE, 0) : x + HALF_SIDE] = colour
    return image


def push_episodes(num: int, gen: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """Frames ``[E, T+1, H, W, 3]`` and pushes ``[E, T, 4]`` (start x, y, end x, y)."""
    frames, actions = [], []
    for _ in range(num):
        pos = torch.rand(2, 2, generator=gen) * 1.2 - 0.6
        episode_frames, episode_actions = [render(pos)], []
        for _ in range(PUSHES):
            k = int(torch.randint(2, (1,), generator=gen))
            angle = float(torch.rand(1, generator=gen)) * 2 * math.pi
            length = 0.2 + 0.3 * float(torch.rand(1, generator=gen))
            direction = torch.tensor([math.cos(angle), math.sin(angle)])
            end = (pos[k] + length * direction).clamp(-0.7, 0.7)
            episode_actions.append(torch.cat([pos[k] - 0.2 * direction, end]))
            pos = pos.clone()
            pos[k] = end
            episode_frames.append(render(pos))
        frames.append(torch.stack(episode_frames))
        actions.append(torch.stack(episode_actions))
    return torch.stack(frames), torch.stack(actions)


def transitions(
    frames: torch.Tensor, actions: torch.Tensor, episode: torch.Tensor, step: torch.Tensor
) -> TensorDict:
    return TensorDict(
        {
            PIXELS_0: frames[episode, 0],
            PIXELS: frames[episode, step],
            ACTION: actions[episode, step],
            "next": {PIXELS: frames[episode, step + 1]},
        },
        batch_size=[len(episode)],
    )


@pytest.fixture(scope="module")
def trained() -> dict[str, float]:
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tiny ops: extra threads only add sync cost on a busy CI machine
    try:
        return train_and_measure()
    finally:
        torch.set_num_threads(threads)


def train_and_measure() -> dict[str, float]:
    """Trains on synthetic pushes; returns losses and keypoint errors on held-out transitions."""
    gen = torch.Generator().manual_seed(SEED)
    frames, actions = push_episodes(64, gen)
    val_frames, val_actions = push_episodes(16, gen)
    val = transitions(
        val_frames,
        val_actions,
        torch.arange(16).repeat_interleave(PUSHES),
        torch.arange(PUSHES).repeat(16),
    )
    torch.manual_seed(SEED)
    model = KINetWorldModel(
        num_keypoints=4,
        feat_dim=8,
        channels=16,
        embed_dim=32,
        hidden_dim=64,
        num_hidden=2,
        num_rounds=2,
    )
    untrained_interaction = copy.deepcopy(model.interaction).eval()
    loss_module = KINetLoss(model)
    with torch.no_grad():
        rec_before = loss_module.eval()(val)["loss_rec"].item()
    loss_module.train()
    optimizer = torch.optim.Adam(loss_module.parameters(), lr=2e-3)
    for _ in range(STEPS):
        episode = torch.randint(len(frames), (BATCH,), generator=gen)
        step = torch.randint(PUSHES, (BATCH,), generator=gen)
        losses = loss_module(transitions(frames, actions, episode, step))
        optimizer.zero_grad()
        sum(losses.values()).backward()
        optimizer.step()
    loss_module.eval()
    with torch.no_grad():
        rec_after = loss_module(val)["loss_rec"].item()
        out = model.transition(val)
        target = out.next_pos

        def error(pred: torch.Tensor) -> float:  # mean squared keypoint error
            return (pred - target).pow(2).sum(-1).mean().item()

        pos, feat = model.detector(val[PIXELS])
        untrained_next = untrained_interaction(pos, feat, val[ACTION]).next_pos
    return {
        "rec_before": rec_before,
        "rec_after": rec_after,
        "fwd_untrained": error(untrained_next),
        "fwd_trained": error(out.prediction.next_pos),
        "no_motion": error(out.pos),
    }


def test_reconstruction_loss_falls(trained):
    assert trained["rec_after"] < trained["rec_before"] / 10, trained


def test_forward_loss_falls(trained):
    assert trained["fwd_trained"] < trained["fwd_untrained"] / 2, trained


def test_forward_prediction_beats_no_motion(trained):
    assert trained["no_motion"] > 0.02, trained  # the keypoints do follow the pushed squares
    assert trained["fwd_trained"] < 0.5 * trained["no_motion"], trained
