"""Planning several rearrangement episodes in one batched planner call: does it pay on this CPU?

Times one GraphMPC plan (the evaluation's default budget: 64 candidates x 3 iterations, K = 6,
horizon 1) over the world model of a default-size KINet (``model.world_model("graph_distance")``
in a :class:`~kinet_rl.planners.PushWorldModelEnv`) for a batch of ``B`` episodes at once, and
reports the time per episode-plan against ``B = 1``. All batch sizes are timed in interleaved
rounds (best round kept) so background load hits them alike.
The last line is ``ratio: X``, the time per episode-plan at the largest batch over ``B = 1``
(below 1: batching episodes is faster).

Usage: python bench/planner_batching.py [--batches 1 2 4 8] [--rounds 3] [--threads 1]
"""

from __future__ import annotations

import argparse
import time

import torch
from tensordict import TensorDict

from kinet_rl.keys import GOAL_PIXELS, PIXELS
from kinet_rl.models import KINetWorldModel
from kinet_rl.planners import GraphMPCPlanner, PushWorldModelEnv

BUDGET = {"planning_horizon": 1, "optim_steps": 3, "num_candidates": 64, "top_k": 8}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 2, 4, 8])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--calls", type=int, default=4, help="plans timed per round")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (a worker uses 1)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    world_model = KINetWorldModel().eval().world_model("graph_distance")
    env = PushWorldModelEnv(world_model)
    images = torch.randint(0, 256, (2, 64, 64, 3), dtype=torch.uint8)
    start = world_model.observe(TensorDict({PIXELS: images[0], GOAL_PIXELS: images[1]}, []))
    planners = {b: GraphMPCPlanner(env, **BUDGET) for b in args.batches}
    states = {b: start.expand(b).clone() if b > 1 else start for b in args.batches}
    best = {b: float("inf") for b in args.batches}
    for _ in range(args.rounds):
        for b in args.batches:
            planners[b](states[b])  # warm-up
            t0 = time.perf_counter()
            for _ in range(args.calls):
                planners[b].reset()
                planners[b](states[b])
            best[b] = min(best[b], (time.perf_counter() - t0) / args.calls / b)
    print(f"threads {args.threads}, budget {BUDGET}")
    print("| episodes per call | ms per episode-plan | vs one episode |")
    print("|---:|---:|---:|")
    for b in args.batches:
        print(f"| {b} | {1e3 * best[b]:.1f} | {best[b] / best[args.batches[0]]:.2f} |")
    print(f"ratio: {best[max(args.batches)] / best[args.batches[0]]:.3f}")


if __name__ == "__main__":
    main()
