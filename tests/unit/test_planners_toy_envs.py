"""Contract tests of the toy model envs of the planner tests (``tests/toy_model_envs.py``)."""

from __future__ import annotations

import torch
from torchrl.envs.utils import check_env_specs

from kinet_rl.keys import ACTION, KP_POS
from toy_model_envs import QuadraticModelEnv, TrapModelEnv


def test_quadratic_env_specs_and_dynamics() -> None:
    env = QuadraticModelEnv(goal=torch.tensor([[1.0, -1.0]]))
    check_env_specs(env)
    td = env.reset()
    td.set(ACTION, torch.tensor([0.5, -0.25]))
    out = env.step(td)["next"]
    assert torch.allclose(out[KP_POS], torch.tensor([[0.5, -0.25]]))
    assert torch.allclose(out["reward"], torch.tensor([-(0.25 + 0.5625)]))


def test_trap_env_specs_and_done() -> None:
    env = TrapModelEnv()
    check_env_specs(env)
    td = env.reset()
    td.set(ACTION, torch.tensor([-1.0]))
    out = env.step(td)["next"]
    assert out["done"].item() and out["reward"].item() == -1.0
