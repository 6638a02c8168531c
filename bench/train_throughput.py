"""Training throughput: the Trainer's KINet step against a bare PyTorch loop, and its fast settings.

Usage: ``python bench/train_throughput.py [--image-size 64] [--batch 32] [--rounds 20] [--compile]``

Every variant trains the default KINet (default sizes) with the default experiment's losses
(``conf/loss/kinet.yaml``: the four paper losses plus the rollout loss over the 2 pushes after
each transition, ``trainer.horizon=3``) and gradient clipping at 10, on the same batch each
round, drawn from in-memory uint8 frames ``[E, T+1, H, W, 3]`` (the loader is timed by
``loader_throughput.py``). kinet_rl's step is ``Trainer.train_step``: ``KINetLoss``, backward,
clipping, Adam. The bare loop gathers plain tensors and calls the detector, reconstructor
and interaction net directly with the losses written inline (no TensorDict, no LossModule, the
textbook ``torch.optim.Adam``). Variants of the Trainer's step:

* ``plain eager``: ``TrainerSettings`` defaults (float32, not compiled);
* ``channels_last weights``: the model converted to channels-last (a candidate; no gain);
* ``precision=bfloat16``: the forward under bfloat16 autocast;
* with ``--compile`` also ``compile=True`` alone and with bfloat16 (their warm-up compiles for
  minutes; the compile time is printed).

After a warm-up the variants take one step each in turn for ``--rounds`` rounds, so that load
changes on a shared machine hit all alike; median step times are reported. The last two lines:
``speedup: X`` = the optimised step (bfloat16, and compiled with ``--compile``) over the plain
eager step, samples/s; ``ratio: X`` = the plain eager step over the bare loop.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import torch
from tensordict import TensorDict

from kinet_rl.keys import ACTION, FUTURE_ACTION, FUTURE_PIXELS, NEXT_PIXELS, PIXELS, PIXELS_0
from kinet_rl.models import KINetLoss, KINetWorldModel, graph_info_nce
from kinet_rl.models.keypoints import pixels_to_input
from kinet_rl.training import TrainingCheckpoint
from kinet_rl.training.loggers import make_logger
from kinet_rl.training.loop import Trainer, TrainerSettings

EPISODES, PUSHES, HORIZON = 32, 10, 3
ROLLOUT_WEIGHT, GRAD_CLIP = 1.0, 10.0  # conf/loss/kinet.yaml, conf/config.yaml

Step = Callable[[TensorDict], None]


def random_batch(
    frames: torch.Tensor, actions: torch.Tensor, batch: int, gen: torch.Generator
) -> TensorDict:
    """A ``PushDataset.sample(batch, horizon=HORIZON)``-style batch of random transitions."""
    episode = torch.randint(EPISODES, (batch,), generator=gen)
    step = torch.randint(PUSHES - HORIZON + 1, (batch,), generator=gen)
    times = torch.stack([torch.zeros_like(step), step, step + 1], dim=1)
    ahead = step[:, None] + torch.arange(1, HORIZON)  # the pushes after each transition
    picked = frames[episode[:, None], times]
    return TensorDict(
        {
            PIXELS_0: picked[:, 0],
            PIXELS: picked[:, 1],
            ACTION: actions[episode, step],
            "next": {PIXELS: picked[:, 2]},
            FUTURE_PIXELS: frames[episode[:, None], ahead + 1],
            FUTURE_ACTION: actions[episode[:, None], ahead],
        },
        batch_size=[batch],
    )


class RoundBatch:
    """A sampler that hands the Trainer the batch of the current round."""

    def __init__(self) -> None:
        self.batch: TensorDict | None = None

    def sample(self, batch_size: int, generator: torch.Generator | None = None, **_) -> TensorDict:
        assert self.batch is not None and self.batch.shape[0] == batch_size
        return self.batch


def trainer_step(model: KINetWorldModel, run_dir: Path, batch: int, **settings) -> Step:
    """``Trainer.train_step`` of ``KINetLoss(model)`` with the given ``TrainerSettings``."""
    data = RoundBatch()
    trainer = Trainer(
        KINetLoss(model, rollout_weight=ROLLOUT_WEIGHT),
        data,
        data,
        TrainerSettings(batch_size=batch, horizon=HORIZON, grad_clip=GRAD_CLIP, **settings),
        TrainingCheckpoint(run_dir, {"bench": "train_throughput"}),
        make_logger("csv", run_dir, "bench"),
    )

    def step(td: TensorDict) -> None:
        data.batch = td
        trainer.train_step()

    return step


def bare_step(model: KINetWorldModel) -> Step:
    """The same losses written inline on plain tensors (weights 1, 1, 0.01, 0.1, 1)."""
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    det, rec, net = model.detector, model.reconstructor, model.interaction

    def step(td: TensorDict) -> None:
        first, current, following = td[PIXELS_0], td[PIXELS], td[NEXT_PIXELS]
        action, future, future_actions = td[ACTION], td[FUTURE_PIXELS], td[FUTURE_ACTION]
        n = len(first)
        with torch.no_grad():  # I_0 and I_t+1 in one pass, the rollout's frames in another
            source, target = det.encode(torch.cat([first, following])).split(n)
            rollout_target = det(future)[0]
        observed = det.encode(current)
        image = rec(source, observed)
        loss_rec = (image - pixels_to_input(current).permute(0, 2, 3, 1)).pow(2).mean()
        pred = net(observed.pos.detach(), observed.feat, action)
        loss_fwd = (pred.next_pos - target.pos).pow(2).sum(dim=(-2, -1)).mean()
        loss_ctr = graph_info_nce(pred.next_nodes, net.embed_nodes(target.pos, target.feat))
        pos, rollout = pred.next_pos, []
        for h in range(HORIZON - 1):
            pos = net(pos, observed.feat, future_actions[:, h]).next_pos
            rollout.append(pos)
        error = (torch.stack(rollout, dim=1) - rollout_target).pow(2).sum(dim=(-2, -1))
        loss = loss_rec + loss_fwd + 0.01 * pred.kl.mean() + 0.1 * loss_ctr
        loss = loss + ROLLOUT_WEIGHT * error.mean()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), GRAD_CLIP)
        optimizer.step()

    return step


def seconds(step: Step, td: TensorDict) -> float:
    """Wall time of one training step on ``td``."""
    start = time.perf_counter()
    step(td)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--image-size", type=int, default=64)
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--rounds", type=int, default=20, help="timed steps per variant")
    parser.add_argument("--compile", action="store_true", help="also time compile=True")
    args = parser.parse_args()
    gen = torch.Generator().manual_seed(0)
    size = args.image_size
    frames = torch.randint(0, 256, (EPISODES, PUSHES + 1, size, size, 3), generator=gen).byte()
    actions = torch.rand(EPISODES, PUSHES, 4, generator=gen) * 2 - 1

    def fresh_model() -> KINetWorldModel:
        torch.manual_seed(0)
        return KINetWorldModel()

    with tempfile.TemporaryDirectory() as tmp:
        runs = iter(Path(tmp, str(i)) for i in range(100))
        variants: dict[str, Step] = {
            "bare loop": bare_step(fresh_model()),
            "plain eager": trainer_step(fresh_model(), next(runs), args.batch),
            "channels_last weights": trainer_step(
                fresh_model().to(memory_format=torch.channels_last), next(runs), args.batch
            ),
            "precision=bfloat16": trainer_step(
                fresh_model(), next(runs), args.batch, precision="bfloat16"
            ),
        }
        optimised = "precision=bfloat16"
        if args.compile:
            variants["compile"] = trainer_step(fresh_model(), next(runs), args.batch, compile=True)
            optimised = "compile, precision=bfloat16"
            variants[optimised] = trainer_step(
                fresh_model(), next(runs), args.batch, compile=True, precision="bfloat16"
            )
        warm_up: dict[str, float] = {}
        for name, step in variants.items():
            warm_up[name] = sum(seconds(step, random_batch(frames, actions, args.batch, gen))
                                for _ in range(3))  # fmt: skip
        times: dict[str, list[float]] = {name: [] for name in variants}
        for _ in range(args.rounds):
            td = random_batch(frames, actions, args.batch, gen)
            for name, step in variants.items():
                times[name].append(seconds(step, td))
    rates = {name: args.batch / statistics.median(values) for name, values in times.items()}
    base, plain = rates["bare loop"], rates["plain eager"]
    print(
        f"threads: {torch.get_num_threads()}, {size} px, batch {args.batch}, horizon {HORIZON}, "
        f"{args.rounds} rounds"
    )
    print(f"{'variant':30s} {'samples/s':>10s} {'vs bare':>8s} {'vs plain':>9s} {'warm-up s':>10s}")
    for name, rate in rates.items():
        print(
            f"{name:30s} {rate:10.1f} {rate / base:8.2f} {rate / plain:9.2f} {warm_up[name]:10.1f}"
        )
    print(f"speedup: {rates[optimised] / plain:.3f}")
    print(f"ratio: {plain / base:.3f}")


if __name__ == "__main__":
    main()
