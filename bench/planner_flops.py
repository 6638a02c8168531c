"""Planner FLOPs: KINet's world model's fast path against the straightforward computation, per plan.

For each K and horizon, a randomly initialised KINet of the default size (64x64 images,
objective ``graph``: the cosine graph similarity) plans one push with GraphMPC (CEM,
``candidates`` x ``iterations``) twice from the same images and planner seed, over a
``PushWorldModelEnv`` of ``model.world_model("graph")`` (fast: goal graph kept per goal image,
the start graph encoded once for all candidates, edges without self-loops, pair MLPs split per
node) and of ``model.world_model("graph", fast=False)`` (the straightforward computation).
torch's ``FlopCounterMode`` counts the FLOPs of one control step, ``world_model.observe``
(detector on the current image, goal graph) plus the plan, after each world model has seen the
goal once.
The largest difference between the two planned pushes is printed as a check that both compute the
same function. The last line is ``ratio: X``, the geometric mean over settings of the fast FLOPs
over the straightforward FLOPs per plan.

Usage: python bench/planner_flops.py [--keypoints 6 9] [--horizons 1 3] [--candidates 256]
"""

from __future__ import annotations

import argparse
import math

import torch
from tensordict import TensorDict
from torch.utils.flop_counter import FlopCounterMode

from kinet_rl.keys import ACTION, GOAL_PIXELS, PIXELS
from kinet_rl.models import KINetWorldModel
from kinet_rl.planners import GraphMPCPlanner, PushWorldModel, PushWorldModelEnv


def control_step_flops(
    world_model: PushWorldModel, planner: GraphMPCPlanner, observation: TensorDict
) -> tuple[int, int, torch.Tensor]:
    """FLOPs of ``observe`` and of one plan, and the planned push."""
    with FlopCounterMode(display=False) as counter:
        state = world_model.observe(observation)
    observe = counter.get_total_flops()
    with FlopCounterMode(display=False) as counter:
        push = planner(state)[ACTION]
    return observe, counter.get_total_flops(), push


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keypoints", type=int, nargs="+", default=[6, 9])
    parser.add_argument("--horizons", type=int, nargs="+", default=[1, 3])
    parser.add_argument("--candidates", type=int, default=256)
    parser.add_argument("--iterations", type=int, default=5)
    parser.add_argument("--top-k", type=int, default=32)
    args = parser.parse_args()
    torch.manual_seed(0)
    pixels, goal = torch.randint(0, 256, (2, 64, 64, 3), dtype=torch.uint8)
    observation = TensorDict({PIXELS: pixels, GOAL_PIXELS: goal}, [])
    print(
        f"candidates={args.candidates} iterations={args.iterations} top_k={args.top_k}; "
        "GFLOP per control step (observe + plan)"
    )
    header = (
        f"{'K':>2} {'H':>2} | {'observe':>7} {'plan':>8} | {'fast obs':>8} {'fast plan':>9} | "
        f"{'ratio':>5} | {'max |push diff|':>15}"
    )
    print(header)
    print("-" * len(header))
    log_ratio = 0.0
    settings = [(k, h) for k in args.keypoints for h in args.horizons]
    for num_keypoints, horizon in settings:
        model = KINetWorldModel(num_keypoints=num_keypoints).eval()
        flops, pushes = {}, {}
        for fast in (False, True):
            world_model = model.world_model("graph", fast=fast)
            planner = GraphMPCPlanner(
                PushWorldModelEnv(world_model),
                planning_horizon=horizon,
                optim_steps=args.iterations,
                num_candidates=args.candidates,
                top_k=args.top_k,
                generator=torch.Generator().manual_seed(1),
            )
            world_model.observe(observation)  # the goal was seen at the episode's first step
            *flops[fast], pushes[fast] = control_step_flops(world_model, planner, observation)
        ratio = sum(flops[True]) / sum(flops[False])
        log_ratio += math.log(ratio)
        diff = (pushes[True] - pushes[False]).abs().max().item()
        (obs, plan), (fast_obs, fast_plan) = flops[False], flops[True]
        print(
            f"{num_keypoints:>2} {horizon:>2} | {obs / 1e9:>7.3f} {plan / 1e9:>8.2f} | "
            f"{fast_obs / 1e9:>8.3f} {fast_plan / 1e9:>9.2f} | {ratio:>5.3f} | {diff:>15.1e}"
        )
    print(f"ratio: {math.exp(log_ratio / len(settings)):.3f}")


if __name__ == "__main__":
    main()
