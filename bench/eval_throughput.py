"""Rearrangement evaluation throughput: episodes batched into one planner call against one at a time.

Runs the same rearrangement episodes (the evaluation's defaults: the shipped ``blocks_topview``
KINet, its planner ``kinet_keypoints_l2`` at the 64 x 3 budget, T = 40 pushes, test seeds) with
``batch_episodes = 1`` and with each larger batch size, in interleaved rounds (best round kept)
so that background load hits them alike, through the real runner (``workers`` spawn processes,
one torch thread each; use at least ``workers x`` the largest batch episodes, so that every
batch size keeps all workers busy). It prints episodes per minute, and whether the batched runs reproduce
the one-at-a-time episodes: how many final distances agree to 1e-6 m, and the largest
difference. The last line is ``ratio: X``, episodes per minute at the largest batch over one
at a time (above 1: batching is faster).

Usage: python bench/eval_throughput.py [--episodes 16] [--batches 1 4 8] [--workers 2] [--rounds 2]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from kinet_rl.models import KINetWorldModel
from kinet_rl.models.checkpointing import checkpoint_scene
from kinet_rl.models.pretrained import pretrained_path
from kinet_rl.rearrangement import RearrangementSettings, TaskSettings, run_rearrangement


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=16)
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 4, 8])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--steps", type=int, default=40, help="pushes per episode (T)")
    args = parser.parse_args()
    if args.episodes < args.workers * max(args.batches):
        parser.error("--episodes must be at least --workers x the largest batch (idle workers).")
    checkpoint = pretrained_path("blocks_topview")
    model = KINetWorldModel.from_checkpoint(checkpoint)
    settings = {
        b: RearrangementSettings(
            scene=checkpoint_scene(checkpoint),
            task=TaskSettings(num_steps=args.steps),
            episodes=args.episodes,
            methods=("kinet_keypoints_l2",),
            workers=args.workers,
            batch_episodes=b,
            videos=0,
        )
        for b in args.batches
    }
    best = {b: float("inf") for b in args.batches}
    finals: dict[int, np.ndarray] = {}
    for _ in range(args.rounds):
        for b in args.batches:
            start = time.perf_counter()
            results = run_rearrangement(model, settings[b])
            best[b] = min(best[b], time.perf_counter() - start)
            (by_method,) = results.episodes.values()
            finals[b] = np.array([r.distances[-1] for r in by_method["kinet_keypoints_l2"]])
    one = args.batches[0]
    print(
        f"{args.episodes} episodes x {args.steps} pushes, {args.workers} workers, "
        f"best of {args.rounds} rounds; planner {dict(settings[one].planner)}"
    )
    print("| episodes per call | episodes/min | vs one at a time | same finals | max diff (mm) |")
    print("|---:|---:|---:|---:|---:|")
    for b in args.batches:
        diff = np.abs(finals[b] - finals[one])
        print(
            f"| {b} | {60 * args.episodes / best[b]:.1f} | {best[one] / best[b]:.2f} | "
            f"{int((diff <= 1e-6).sum())}/{len(diff)} | {1e3 * diff.max():.2f} |"
        )
    print(f"ratio: {best[one] / best[max(args.batches)]:.3f}")


if __name__ == "__main__":
    main()
