"""Collection throughput: frames/s of collect_dataset with 1 and 2 workers vs one raw env.

Usage: MUJOCO_GL=egl python bench/collect_throughput.py [--episodes 60] [--raw-steps 240]

Collection is timed end to end (worker start-up, policy, assembly, memmap writes, shutdown);
the baseline steps one ``make_env`` env with uniform random actions in this process, before,
between and after the two collection runs (median), so that a change in machine load hits
both sides. The last line is ``ratio: X`` = 2-worker collection frames/s over the raw
single-env step rate.
"""

from __future__ import annotations

import argparse
import functools
import logging
import statistics
import tempfile
import time

import torch

from kinet_rl.data import collect_dataset
from kinet_rl.envs import make_env

ENV_CONFIG = {
    "task": "blocks",
    "num_objects": 3,
    "camera": "top",
    "image_size": 64,
    "max_steps": 60,
}


def raw_step_rate(num_steps: int) -> float:
    """Steps/s of one env stepped with uniform random actions (auto-resets included)."""
    env = make_env(**ENV_CONFIG, seed=0)
    env.rollout(5)  # warm up rendering
    start = time.perf_counter()
    env.rollout(num_steps, break_when_any_done=False)
    rate = num_steps / (time.perf_counter() - start)
    env.close()
    return rate


def collection_rate(num_workers: int, num_episodes: int, root: str) -> float:
    """Frames (pushes) per second of a full collect_dataset run."""
    env_fn = functools.partial(make_env, **ENV_CONFIG)
    start = time.perf_counter()
    collect_dataset(
        env_fn,
        ENV_CONFIG,
        root=root,
        name=f"bench_{num_workers}w",
        num_episodes=num_episodes,
        num_workers=num_workers,
        progress=False,
    )
    return num_episodes * ENV_CONFIG["max_steps"] / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=60, help="episodes per collection run")
    parser.add_argument("--raw-steps", type=int, default=240, help="steps of the raw baseline")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    torch.set_num_threads(1)
    raws = [raw_step_rate(args.raw_steps)]
    with tempfile.TemporaryDirectory() as root:
        one = collection_rate(1, args.episodes, root)
        raws.append(raw_step_rate(args.raw_steps))
        two = collection_rate(2, args.episodes, root)
        raws.append(raw_step_rate(args.raw_steps))
    raw = statistics.median(raws)
    print(f"raw single env: {raw:.1f} steps/s (median of {', '.join(f'{r:.1f}' for r in raws)})")
    print(f"collect 1 worker: {one:.1f} frames/s ({one / raw:.2f}x raw)")
    print(f"collect 2 workers: {two:.1f} frames/s ({two / raw:.2f}x raw)")
    print(f"ratio: {two / raw:.2f}")


if __name__ == "__main__":
    main()
