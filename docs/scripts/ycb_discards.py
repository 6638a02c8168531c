"""Unstable YCB episodes per object under the collection policy, over a range of seeds.

    MUJOCO_GL=egl python docs/scripts/ycb_discards.py --episodes 150 --first-seed 1000

Each episode draws 3 of the objects in $KINET_RL_YCB_DIR and runs 60 pushes of the
``RandomPushPolicy`` with the YCB experiments' settings (``conf/exp/ycb_*view.yaml``). Prints
the discarded (unstable) episodes per object, the reasons, the pushes that started on top of an
object (the pusher retracts) and the pushes after which an object centre lies more than 3 cm
outside the top camera's view.
"""

from __future__ import annotations

import argparse
import collections
import logging
import time

import numpy as np
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from kinet_rl.configs import config_dir
from kinet_rl.data.policy import RandomPushPolicy
from kinet_rl.envs import make_dm_env
from kinet_rl.envs.scene import CAMERA_FRAMINGS
from kinet_rl.envs.task import PushObjects


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=150)
    parser.add_argument("--first-seed", type=int, default=1000)
    args = parser.parse_args()
    with initialize_config_dir(config_dir(), version_base=None):
        policy_settings = OmegaConf.to_container(
            compose("config", overrides=["+exp=ycb_topview"]).data.policy
        )
    reasons: list[str] = []

    class Record(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            reasons.append(record.getMessage().split("(", 1)[1].split(");")[0])

    task_log = logging.getLogger("kinet_rl.envs.task")
    task_log.addHandler(Record())
    task_log.propagate = False
    blocked = collections.Counter()
    original = PushObjects._hold_pusher_and_check_blocked

    def counting(self, physics, target):
        result = original(self, physics, target)
        blocked[result] += 1
        return result

    PushObjects._hold_pusher_and_check_blocked = counting
    seen, discarded, outside = collections.Counter(), collections.Counter(), 0
    view = CAMERA_FRAMINGS["ycb"].top_view + 0.03
    start = time.perf_counter()
    for seed in range(args.first_seed, args.first_seed + args.episodes):
        env = make_dm_env(task="ycb", num_objects=3, seed=seed, image_size=16)
        ts, task = env.reset(), env.task
        half = task.workspace.half_size
        policy = RandomPushPolicy(half, **policy_settings)
        rng = np.random.default_rng(seed)
        for _ in range(60):
            ts = env.step(policy.sample_push(rng, ts.observation["object_pos"] / half))
            if task.unstable:
                break
            outside += bool(np.abs(ts.observation["object_pos"]).max() > view)
        seen.update(name.removeprefix("ycb_") for name in task.active)
        if task.unstable:
            discarded.update(name.removeprefix("ycb_") for name in task.active)
        env.close()
    pushes = blocked[True] + blocked[False]
    print(
        f"{len(reasons)} of {args.episodes} episodes unstable (seeds {args.first_seed}+), "
        f"{time.perf_counter() - start:.0f} s"
    )
    print("reasons:", dict(collections.Counter(reasons)))
    print(f"pushes that started on an object: {blocked[True]} of {pushes}")
    print(f"pushes leaving an object centre > 3 cm outside the top view: {outside} of {pushes}")
    print("| object | episodes | discarded |\n|---|---:|---:|")
    for name in sorted(seen):
        print(f"| {name} | {seen[name]} | {discarded[name]} |")


if __name__ == "__main__":
    main()
