"""Throughput of ``kinet_rl.envs.make_env`` against raw MuJoCo doing the same work.

For each task a TorchRL env executes random pushes, counting the physics steps of every push.
The baseline builds ``mujoco.MjModel`` from the same XML (with the episode's sampled sizes,
colours and mass properties copied in), starts from the same state and replays each push with
plain ``mujoco``: the same pusher placement and velocity commands (``PushObjects.push_plan``),
``mujoco.mj_step`` with the same step counts, one frame with ``mujoco.Renderer``. The replay
reaches the same state (the largest qpos gap is printed).
``frames_s`` compares rendering alone. Both run alternately for several rounds in the same
process (the median is reported), so machine load affects both alike.

Usage: ``MUJOCO_GL=egl python bench/env_throughput.py [--pushes 20] [--rounds 11] [--ycb-dir DIR]``.
Each metric is the median over rounds (ratios: median of per-round ratios). The last line is
``ratio: X``: kinet_rl pushes/s over raw pushes/s, mean over tasks.
"""

from __future__ import annotations

import argparse
import os
import time

import mujoco
import numpy as np
import torch

from kinet_rl.envs import make_env
from kinet_rl.envs.scene import PUSHER_PARK, blocks_scene_xml, ycb_scene_xml
from kinet_rl.envs.textures import table_texture_assets
from kinet_rl.envs.ycb import load_ycb_objects

# Model fields the task rewrites per episode; copied into the baseline model.
EPISODE_FIELDS = (
    "geom_size",
    "geom_pos",
    "geom_rbound",
    "geom_aabb",
    "geom_rgba",
    "geom_matid",
    "geom_contype",
    "geom_conaffinity",
    "body_mass",
    "body_ipos",
    "body_iquat",
    "body_inertia",
    "body_gravcomp",
    "mat_rgba",
)
NUM_OBJECTS = 3
IMAGE_SIZE = 64


class KinetRunner:
    """Pushes through the TorchRL env, recording physics steps per push."""

    def __init__(self, task: str, ycb_dir: str | None) -> None:
        self.env = make_env(
            task=task, num_objects=NUM_OBJECTS, seed=0, max_steps=None, ycb_dir=ycb_dir
        )
        self.dm = self.env._env
        self.td = self.env.reset()
        self.generator = torch.Generator().manual_seed(0)

    def state(self) -> tuple[np.ndarray, ...]:
        data = self.dm.physics.data
        return data.qpos.copy(), data.qvel.copy(), data.act.copy(), data.qacc_warmstart.copy()

    def pushes(self, count: int) -> tuple[float, torch.Tensor, list[int]]:
        actions = torch.rand(count, 4, generator=self.generator) * 2 - 1
        physics, steps = self.dm.physics, []
        start = time.perf_counter()
        for action in actions:
            t0 = physics.data.time
            self.td = self.env.step(self.td.set("action", action))["next"]
            steps.append(round((physics.data.time - t0) / physics.model.opt.timestep))
            if self.td["done"].item():
                self.td = self.env.reset()
        return count / (time.perf_counter() - start), actions, steps

    def frames(self, count: int) -> float:
        start = time.perf_counter()
        for _ in range(count):
            self.dm.task.render(self.dm.physics)
        return count / (time.perf_counter() - start)


class RawRunner:
    """The same physics steps and renders with plain ``mujoco``."""

    def __init__(self, task: str, kinet: KinetRunner, ycb_dir: str | None) -> None:
        workspace = kinet.dm.task.workspace
        if task == "blocks":
            xml, _ = blocks_scene_xml(workspace, NUM_OBJECTS, IMAGE_SIZE)
        else:
            xml, _ = ycb_scene_xml(workspace, load_ycb_objects(ycb_dir), IMAGE_SIZE)
        self.model = mujoco.MjModel.from_xml_string(xml, table_texture_assets())
        self.data = mujoco.MjData(self.model)
        self.renderer = mujoco.Renderer(self.model, IMAGE_SIZE, IMAGE_SIZE)
        self.kinet = kinet

    def sync(self) -> None:
        """Copy the kinet env's episode model fields and state."""
        for field in EPISODE_FIELDS:
            getattr(self.model, field)[:] = getattr(self.kinet.dm.physics.model.ptr, field)
        mujoco.mj_setConst(self.model, self.data)
        qpos, qvel, act, warmstart = self.kinet.state()
        self.data.qpos[:], self.data.qvel[:], self.data.act[:] = qpos, qvel, act
        self.data.qacc_warmstart[:] = warmstart

    def pushes(self, actions: torch.Tensor, steps: list[int]) -> float:
        """Replay the pushes: same pusher placement, moves, step counts, one render each."""
        model, data, task = self.model, self.data, self.kinet.dm.task
        joints = [model.joint(f"pusher_{a}").id for a in "xyz"]
        qpos_ids, dof_ids = model.jnt_qposadr[joints], model.jnt_dofadr[joints]
        act_ids = model.actuator_actadr[[model.actuator(f"pusher_{a}").id for a in "xyz"]]
        dt = model.opt.timestep
        start = time.perf_counter()
        for action, nstep in zip(actions.numpy(), steps, strict=True):
            above_start, moves = task.push_plan(action)
            data.qpos[qpos_ids], data.qvel[dof_ids], data.act[act_ids] = (
                above_start,
                0.0,
                above_start,
            )
            moved = 0
            for target, speed in moves:
                delta = target - data.act[act_ids]
                n = max(1, int(np.ceil(np.linalg.norm(delta) / (speed * dt))))
                data.ctrl[:] = delta / (n * dt)
                mujoco.mj_step(model, data, nstep=n)
                moved += n
            data.ctrl[:] = 0.0
            data.qpos[qpos_ids], data.qvel[dof_ids], data.act[act_ids] = (
                PUSHER_PARK,
                0.0,
                PUSHER_PARK,
            )
            mujoco.mj_step(model, data, nstep=nstep - moved)
            self.renderer.update_scene(data, camera="top")
            self.renderer.render()
        return len(steps) / (time.perf_counter() - start)

    def max_state_difference(self) -> float:
        """Largest qpos difference to the kinet env (0 when the replay matched exactly)."""
        return float(np.abs(self.data.qpos - self.kinet.dm.physics.data.qpos).max())

    def frames(self, count: int) -> float:
        start = time.perf_counter()
        for _ in range(count):
            self.renderer.update_scene(self.data, camera="top")
            self.renderer.render()
        return count / (time.perf_counter() - start)


def bench_task(task: str, pushes: int, rounds: int, ycb_dir: str | None) -> dict[str, np.ndarray]:
    """Per-round ``[kinet, raw, ratio]`` rows for each metric, medians over rounds."""
    kinet = KinetRunner(task, ycb_dir)
    raw = RawRunner(task, kinet, ycb_dir)
    rows: dict[str, list[tuple[float, float, float]]] = {"pushes_s": [], "frames_s": []}
    mean_steps, state_gaps = [], []
    for _ in range(rounds):
        raw.sync()
        kinet_rate, actions, steps = kinet.pushes(pushes)
        raw_rate = raw.pushes(actions, steps)
        state_gaps.append(raw.max_state_difference())
        rows["pushes_s"].append((kinet_rate, raw_rate, kinet_rate / raw_rate))
        kinet_fps, raw_fps = kinet.frames(pushes), raw.frames(pushes)
        rows["frames_s"].append((kinet_fps, raw_fps, kinet_fps / raw_fps))
        mean_steps.append(np.mean(steps))
    raw.renderer.close()
    result = {key: np.median(np.array(vals), axis=0) for key, vals in rows.items()}
    result["steps"] = np.array([np.mean(mean_steps)])
    result["state_gap"] = np.array([np.max(state_gaps)])
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pushes", type=int, default=20, help="pushes per round")
    parser.add_argument("--rounds", type=int, default=11)
    parser.add_argument("--ycb-dir", default=None)
    args = parser.parse_args()
    tasks = ["blocks"] + (["ycb"] if args.ycb_dir or os.environ.get("KINET_RL_YCB_DIR") else [])
    print(f"{'task':8s} {'metric':9s} {'kinet_rl':>9s} {'raw':>9s} {'ratio':>6s}")
    ratios = []
    for task in tasks:
        res = bench_task(task, args.pushes, args.rounds, args.ycb_dir)
        for metric in ("pushes_s", "frames_s"):
            kinet_value, raw_value, ratio = res[metric]
            print(f"{task:8s} {metric:9s} {kinet_value:9.1f} {raw_value:9.1f} {ratio:6.3f}")
        print(
            f"{task:8s} steps/push {res['steps'][0]:.0f}, replay max |qpos| gap {res['state_gap'][0]:.2e}"
        )
        ratios.append(res["pushes_s"][2])
    print(f"ratio: {np.mean(ratios):.3f}")


if __name__ == "__main__":
    main()
