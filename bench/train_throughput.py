"""Training throughput: samples/s of a ``KINetLoss`` step against a bare PyTorch loop.

Usage: ``python bench/train_throughput.py [--image-size 64] [--batch 32] [--rounds 20]``

Both loops train the same model (default KINet sizes) on the same in-memory uint8 frames
``[E, T+1, H, W, 3]``. kinet_rl's step is the Trainer's: gather a ``PushDataset``-style
TensorDict batch, ``KINetLoss``, ``total_loss(...).backward()``, Adam. The bare loop gathers
plain tensors and calls the detector, reconstructor and interaction net directly with the losses
written inline (no TensorDict, no LossModule). CPU speed-up candidates are timed in the same
run: channels-last weights (did not pay: kept out of the library), and the former transition
that encoded ``I_0`` with gradient (kinet_rl now encodes ``I_0`` and ``I_t+1`` in one pass
without gradient, which was faster and learnt as well; see ``KINetWorldModel.transition``).
The strided first conv and the pixel-shuffle output layer are built into the model. After a warm-up the variants take one step
each in turn for ``--rounds`` rounds; median step times are reported. The last line is ``ratio: X`` = kinet_rl
samples/s over bare-loop samples/s.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import torch
from tensordict import TensorDict

from kinet_rl.keys import ACTION, PIXELS, PIXELS_0
from kinet_rl.models import KINetLoss, KINetWorldModel, graph_info_nce
from kinet_rl.models.keypoints import pixels_to_input
from kinet_rl.training.loop import total_loss

EPISODES, PUSHES = 32, 10

Step = Callable[[torch.Tensor, torch.Tensor], None]


def kinet_rl_step(loss_module: KINetLoss, frames: torch.Tensor, actions: torch.Tensor) -> Step:
    """The Trainer's step: TensorDict batch, ``KINetLoss``, backward, Adam."""
    optimizer = torch.optim.Adam(loss_module.parameters(), lr=1e-3)

    def step(episode: torch.Tensor, push: torch.Tensor) -> None:
        times = torch.stack([torch.zeros_like(push), push, push + 1], dim=1)
        batch = frames[episode[:, None], times]
        td = TensorDict(
            {
                PIXELS_0: batch[:, 0],
                PIXELS: batch[:, 1],
                ACTION: actions[episode, push],
                "next": {PIXELS: batch[:, 2]},
            },
            batch_size=[len(episode)],
        )
        losses = loss_module(td)
        optimizer.zero_grad(set_to_none=True)
        total_loss(losses).backward()
        optimizer.step()

    return step


def bare_step(
    model: KINetWorldModel, frames: torch.Tensor, actions: torch.Tensor, source_grad: bool = False
) -> Step:
    """The same losses written inline on plain tensors (weights 1, 1, 0.01, 0.1)."""
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    det, rec, net = model.detector, model.reconstructor, model.interaction

    def step(episode: torch.Tensor, push: torch.Tensor) -> None:
        times = torch.stack([torch.zeros_like(push), push, push + 1], dim=1)
        batch = frames[episode[:, None], times]
        n = len(episode)
        if source_grad:  # the former kinet_rl transition: I_0 encoded with gradient
            source, observed = det.encode(batch[:, :2].transpose(0, 1).flatten(0, 1)).split(n)
            with torch.no_grad():
                following = det.encode(batch[:, 2])
        else:  # kinet_rl's transition: I_0 and I_t+1 in one pass without gradient
            with torch.no_grad():
                source, following = det.encode(
                    batch[:, [0, 2]].transpose(0, 1).flatten(0, 1)
                ).split(n)
            observed = det.encode(batch[:, 1])
        image = rec(source, observed)
        target = pixels_to_input(batch[:, 1]).permute(0, 2, 3, 1)
        pred = net(observed.pos.detach(), observed.feat.detach(), actions[episode, push])
        loss_rec = (image - target).pow(2).mean()
        loss_fwd = (pred.next_pos - following.pos).pow(2).sum(dim=(-2, -1)).mean()
        nodes = net.embed_nodes(following.pos, following.feat)
        loss_ctr = graph_info_nce(pred.next_nodes, nodes)
        loss = loss_rec + loss_fwd + 0.01 * pred.kl.mean() + 0.1 * loss_ctr
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()

    return step


def step_seconds(step: Step, batch: int, gen: torch.Generator) -> float:
    """Wall time of one training step on a random batch."""
    episode = torch.randint(EPISODES, (batch,), generator=gen)
    push = torch.randint(PUSHES, (batch,), generator=gen)
    start = time.perf_counter()
    step(episode, push)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--image-size", type=int, default=64)
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--rounds", type=int, default=20, help="timed steps per variant")
    args = parser.parse_args()
    gen = torch.Generator().manual_seed(0)
    size = args.image_size
    frames = torch.randint(0, 256, (EPISODES, PUSHES + 1, size, size, 3), dtype=torch.uint8)
    actions = torch.rand(EPISODES, PUSHES, 4, generator=gen) * 2 - 1

    def fresh_model() -> KINetWorldModel:
        torch.manual_seed(0)
        return KINetWorldModel()

    channels_last = fresh_model().to(memory_format=torch.channels_last)
    variants: dict[str, Step] = {
        "bare loop": bare_step(fresh_model(), frames, actions),
        "kinet_rl KINetLoss": kinet_rl_step(KINetLoss(fresh_model()), frames, actions),
        "kinet_rl + channels_last weights": kinet_rl_step(
            KINetLoss(channels_last), frames, actions
        ),
        "bare loop, I_0 with grad (before)": bare_step(fresh_model(), frames, actions, True),
    }
    for step in variants.values():  # warm-up
        for _ in range(2):
            step_seconds(step, args.batch, gen)
    # One step of each variant in turn, so that load changes on a shared machine hit all alike.
    times: dict[str, list[float]] = {name: [] for name in variants}
    for _ in range(args.rounds):
        for name, step in variants.items():
            times[name].append(step_seconds(step, args.batch, gen))
    rates = {name: args.batch / statistics.median(values) for name, values in times.items()}
    base = rates["bare loop"]
    print(
        f"threads: {torch.get_num_threads()}, {size} px, batch {args.batch}, {args.rounds} rounds"
    )
    print(f"{'variant':36s} {'samples/s':>10s} {'vs bare':>8s}")
    for name, rate in rates.items():
        print(f"{name:36s} {rate:10.1f} {rate / base:8.2f}")
    print(f"ratio: {rates['kinet_rl KINetLoss'] / base:.3f}")


if __name__ == "__main__":
    main()
