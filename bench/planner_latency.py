"""Planner latency: GraphMPCPlanner against torchrl's CEMPlanner on the same graph-like world model.

Every contender plans over the same :class:`~kinet_rl.planners.PushWorldModelEnv`. The stand-in
world model (a :class:`~kinet_rl.planners.PushWorldModel` with objective ``keypoints_l2``) does
message passing over K keypoint nodes (fully connected graph, 128-unit MLPs by default, 3
rounds), so its compute resembles a KINet forward model. For each K and horizon the script times
one plan (``optim_steps`` iterations of ``num_candidates`` rollouts) for torchrl's
``CEMPlanner`` (as shipped, and inside ``torch.no_grad()``), and our planner with the CEM and
MPPI rules, and reports the achieved FLOP rate of our CEM plan (its FLOPs counted by
``FlopCounterMode``) against a large matmul on the same machine (best of before and after the
runs). All contenders are timed in interleaved rounds (best round kept) so background load hits
them alike; process CPU time is reported too, as it is far less sensitive to other processes on a
shared machine. The last line is ``ratio: X``, the geometric mean over settings of our CEM
wall time over torchrl's CEMPlanner wall time (both without autograd); the line before the ratios
gives our CEM's ms per plan in the first setting (by default K = 6, H = 1, 256 x 5).

Our CEM also plans over a plain ``ModelBasedEnvBase`` that runs the same step module (the shape
of the model envs before ``PushWorldModelEnv``): ``env ratio`` is our CEM over
``PushWorldModelEnv`` against it (wall time; the line ``env-ratio:`` is their geometric mean).

``--env kinet`` times the real KINet world model, ``model.world_model("graph")`` (a randomly
initialised KINet of the default size, 64x64 images, objective ``graph``: the cosine graph
similarity) instead of the stand-in, and also our CEM on ``model.world_model("graph",
fast=False)``, the straightforward computation (its ms per plan is on the ms-per-plan line).

Usage: python bench/planner_latency.py [--env graph|kinet] [--repeats 3] [--device cpu] [--hidden 128]
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable

import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torch import Tensor, nn
from torch.utils.flop_counter import FlopCounterMode
from torchrl.envs.model_based import ModelBasedEnvBase
from torchrl.modules.planners import CEMPlanner

from kinet_rl.keys import ACTION, GOAL_KP_POS, GOAL_PIXELS, KP_POS, PIXELS
from kinet_rl.planners import (
    GraphMPCPlanner,
    PushWorldModel,
    PushWorldModelEnv,
    goal_reward_head,
    push_dynamics,
)

ROUNDS = 3
ACTION_DIM = 4


def _mlp(in_dim: int, hidden: int, out_dim: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(in_dim, hidden), nn.ReLU(), nn.Linear(hidden, out_dim))


class MessagePassingDynamics(nn.Module):
    """Predicts next keypoint positions with 3 rounds of message passing over all node pairs."""

    def __init__(self, hidden: int) -> None:
        super().__init__()
        self.hidden = hidden
        self.encode = _mlp(2 + ACTION_DIM, hidden, hidden)
        self.messages = nn.ModuleList(_mlp(2 * hidden, hidden, hidden) for _ in range(ROUNDS))
        self.updates = nn.ModuleList(_mlp(2 * hidden, hidden, hidden) for _ in range(ROUNDS))
        self.decode = _mlp(hidden, hidden, 2)

    def forward(self, pos: Tensor, action: Tensor) -> tuple[Tensor]:
        # pos: [*B, K, 2]; action: [*B, A]
        num_nodes = pos.shape[-2]
        act = action.unsqueeze(-2).expand(*pos.shape[:-1], ACTION_DIM)
        h = self.encode(torch.cat([pos, act], -1))  # [*B, K, D]
        for message, update in zip(self.messages, self.updates, strict=True):
            senders = h.unsqueeze(-3).expand(*h.shape[:-2], num_nodes, num_nodes, self.hidden)
            receivers = h.unsqueeze(-2).expand_as(senders)
            incoming = message(torch.cat([receivers, senders], -1)).mean(-2)  # [*B, K, D]
            h = h + update(torch.cat([h, incoming], -1))
        return (pos + 0.1 * torch.tanh(self.decode(h)),)


def graph_world_model(num_keypoints: int, hidden: int) -> PushWorldModel:
    """The stand-in: K keypoints moved by :class:`MessagePassingDynamics` (4-d push in [-1, 1]),
    the goal keypoints carried along, objective ``keypoints_l2``."""
    return PushWorldModel(
        TensorDictModule(nn.Identity(), in_keys=[KP_POS], out_keys=[KP_POS]),
        push_dynamics(MessagePassingDynamics(hidden), [KP_POS, ACTION], [KP_POS], [GOAL_KP_POS]),
        goal_reward_head("keypoints_l2"),
        {KP_POS: (num_keypoints, 2), GOAL_KP_POS: (num_keypoints, 2)},
    )


class PlainModelEnv(ModelBasedEnvBase):
    """The world model's step module in a plain ``ModelBasedEnvBase`` (what the model envs were
    before ``PushWorldModelEnv``): the reference of ``env ratio``."""

    def __init__(self, env: PushWorldModelEnv) -> None:
        super().__init__(_RootStep(env.world_model), device=env.device, batch_size=torch.Size([]))
        self.observation_spec = env.observation_spec.clone()
        self.action_spec = env.action_spec.clone()
        self.reward_spec = env.reward_spec.clone()

    def _reset(self, tensordict: TensorDict | None = None, **kwargs) -> TensorDict:
        return tensordict.clone()


class _RootStep(TensorDictModule):
    """The step module with its ``("next", ...)`` outputs moved to the root, as the old envs'
    step modules wrote them."""

    def __init__(self, step: nn.Module) -> None:
        nn.Module.__init__(self)
        self.step = step
        self.in_keys, self.out_keys = step.in_keys, step.out_keys

    def forward(self, tensordict: TensorDict) -> TensorDict:
        return tensordict.update(self.step(tensordict).get("next"))


def make_bench_env(kind: str, num_keypoints: int, hidden: int, device: torch.device):
    """The world-model env to plan on, a start state, and for KINet the same env without its fast
    path.

    The stand-in graph world model has no straightforward twin (None).
    """
    if kind == "graph":
        world_model = graph_world_model(num_keypoints, hidden).to(device)
        observation = TensorDict(
            {
                KP_POS: torch.rand(num_keypoints, 2, device=device) * 2 - 1,
                GOAL_KP_POS: torch.rand(num_keypoints, 2, device=device) * 2 - 1,
            },
            batch_size=[],
            device=device,
        )
        straightforward = None
    else:
        from kinet_rl.models import KINetWorldModel

        model = KINetWorldModel(num_keypoints=num_keypoints, hidden_dim=hidden).to(device).eval()
        world_model = model.world_model("graph")
        pixels = torch.randint(0, 256, (2, 64, 64, 3), dtype=torch.uint8, device=device)
        observation = TensorDict({PIXELS: pixels[0], GOAL_PIXELS: pixels[1]}, [], device=device)
        straightforward = PushWorldModelEnv(model.world_model("graph", fast=False), device)
    env = PushWorldModelEnv(world_model, device)
    return env, env.reset(world_model.observe(observation)), straightforward


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def time_interleaved_ms(
    fns: dict[str, Callable[[], object]], rounds: int, device: torch.device
) -> dict[str, tuple[float, float]]:
    """Best (wall, process CPU) time in ms of each function over interleaved rounds.

    Interleaving makes every contender see the same background load, and the minimum discards
    rounds slowed by other processes; process CPU time is far less sensitive to such load.
    """
    best = {name: (float("inf"), float("inf")) for name in fns}
    for fn in fns.values():
        fn()
    for _ in range(rounds):
        for name, fn in fns.items():
            _sync(device)
            wall, cpu = time.perf_counter(), time.process_time()
            fn()
            _sync(device)
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            best[name] = (min(best[name][0], wall * 1e3), min(best[name][1], cpu * 1e3))
    return best


def plan_call(planner: nn.Module, td: TensorDict, no_grad: bool = False) -> Callable[[], None]:
    """One plan from ``td``; ``no_grad`` wraps the call in ``torch.no_grad()``."""

    def plan() -> None:
        with torch.set_grad_enabled(not no_grad):
            planner(td.clone())

    return plan


def matmul_flops_per_s(device: torch.device, size: int = 2048, rounds: int = 5) -> float:
    """Best achieved FLOP rate of a ``size``-square float32 matmul."""
    a = torch.randn(size, size, device=device)
    b = torch.randn(size, size, device=device)
    ms = time_interleaved_ms({"matmul": lambda: a @ b}, rounds, device)["matmul"][0]
    return 2 * size**3 / (ms / 1e3)


def plan_flops(planner: nn.Module, td: TensorDict) -> int:
    """FLOPs of one plan (the world model's: the planner's own arithmetic is negligible)."""
    with FlopCounterMode(display=False) as counter, torch.no_grad():
        planner(td.clone())
    return counter.get_total_flops()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keypoints", type=int, nargs="+", default=[6, 9])
    parser.add_argument("--horizons", type=int, nargs="+", default=[1, 3])
    parser.add_argument("--candidates", type=int, default=256)
    parser.add_argument("--iterations", type=int, default=5)
    parser.add_argument("--top-k", type=int, default=32)
    parser.add_argument("--repeats", type=int, default=3, help="interleaved timing rounds")
    parser.add_argument("--device", default="cpu")
    parser.add_argument(
        "--env",
        choices=("graph", "kinet"),
        default="graph",
        help="stand-in message-passing world model, or the real KINet world model",
    )
    parser.add_argument(
        "--hidden", type=int, default=128, help="MLP width; small values expose planner overhead"
    )
    args = parser.parse_args()
    device = torch.device(args.device)
    torch.manual_seed(0)

    peak_before = matmul_flops_per_s(device)
    rows = []
    common = dict(optim_steps=args.iterations, num_candidates=args.candidates, top_k=args.top_k)
    for num_keypoints in args.keypoints:
        env, td, straightforward_env = make_bench_env(args.env, num_keypoints, args.hidden, device)
        for horizon in args.horizons:
            theirs = CEMPlanner(env, planning_horizon=horizon, **common)
            ours_cem = GraphMPCPlanner(env, planning_horizon=horizon, update_rule="cem", **common)
            ours_mppi = GraphMPCPlanner(env, planning_horizon=horizon, update_rule="mppi", **common)
            contenders = {
                "theirs": plan_call(theirs, td),
                "theirs_no_grad": plan_call(theirs, td, no_grad=True),
                "cem": plan_call(ours_cem, td),
                "mppi": plan_call(ours_mppi, td),
                "cem_plain_env": plan_call(
                    GraphMPCPlanner(
                        PlainModelEnv(env), planning_horizon=horizon, update_rule="cem", **common
                    ),
                    td,
                ),
            }
            if straightforward_env is not None:
                straightforward = GraphMPCPlanner(
                    straightforward_env, planning_horizon=horizon, update_rule="cem", **common
                )
                contenders["cem_straightforward"] = plan_call(straightforward, td)
            times = time_interleaved_ms(contenders, args.repeats, device)
            flops = plan_flops(ours_cem, td)
            rows.append((num_keypoints, horizon, times, flops))
    peak = max(peak_before, matmul_flops_per_s(device))
    print_table(rows, peak, args)


def print_table(rows: list, peak: float, args: argparse.Namespace) -> None:
    """Prints the latency table and, last, the geometric-mean ratio of ours (CEM) to torchrl's."""
    print(
        f"env={args.env} device={args.device} threads={torch.get_num_threads()} hidden={args.hidden} "
        f"candidates={args.candidates} iterations={args.iterations} top_k={args.top_k} "
        f"rounds={args.repeats}; matmul 2048^2 (best): {peak / 1e9:.1f} GFLOP/s"
    )
    header = (
        f"{'K':>2} {'H':>2} | {'torchrl CEM':>11} {'(no_grad)':>10} | {'ours CEM':>9} "
        f"{'ours MPPI':>9} | {'ratio':>5} {'cpu ratio':>9} | {'plain env':>9} {'env ratio':>9} | "
        f"{'GFLOP/plan':>10} {'GFLOP/s':>8} {'% matmul':>8}"
    )
    print(header)
    print("-" * len(header))
    log_ratio = log_cpu_ratio = log_env_ratio = 0.0
    for num_keypoints, horizon, times, flops in rows:
        wall = {name: wall_cpu[0] for name, wall_cpu in times.items()}
        ratio = wall["cem"] / wall["theirs_no_grad"]
        cpu_ratio = times["cem"][1] / times["theirs_no_grad"][1]
        log_ratio += math.log(ratio)
        log_cpu_ratio += math.log(cpu_ratio)
        env_ratio = wall["cem"] / wall["cem_plain_env"]
        log_env_ratio += math.log(env_ratio)
        rate = flops / (wall["cem"] / 1e3)
        print(
            f"{num_keypoints:>2} {horizon:>2} | {wall['theirs']:>9.1f}ms "
            f"{wall['theirs_no_grad']:>8.1f}ms | {wall['cem']:>7.1f}ms {wall['mppi']:>7.1f}ms | "
            f"{ratio:>5.2f} {cpu_ratio:>9.2f} | {wall['cem_plain_env']:>7.1f}ms {env_ratio:>9.2f} | "
            f"{flops / 1e9:>10.2f} {rate / 1e9:>8.1f} "
            f"{100 * rate / peak:>7.1f}%"
        )
    num_keypoints, horizon, times, _ = rows[0]
    line = (
        f"ms per plan (ours CEM, K={num_keypoints}, H={horizon}, {args.candidates} x "
        f"{args.iterations}): {times['cem'][0]:.1f} wall, {times['cem'][1]:.1f} process cpu"
    )
    if "cem_straightforward" in times:
        wall, cpu = times["cem_straightforward"]
        line += f"; straightforward computation: {wall:.1f} wall, {cpu:.1f} process cpu"
    print(line)
    print(f"cpu-time ratio: {math.exp(log_cpu_ratio / len(rows)):.3f}")
    print(f"env-ratio: {math.exp(log_env_ratio / len(rows)):.3f}")
    print(f"ratio: {math.exp(log_ratio / len(rows)):.3f}")


if __name__ == "__main__":
    main()
