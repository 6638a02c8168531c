"""Toy torchrl model envs for the planner tests (their contract tests: ``unit/test_planners_toy_envs.py``).

``QuadraticModelEnv``: K points, push action moves them (next pos = pos + a), reward is minus
the squared distance to a fixed goal. ``TrapModelEnv``: a 1-d env whose rewards after ``done``
would lure a planner that ignores done into the terminating direction.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torch import Tensor, nn
from torchrl.data import Bounded, Composite, Unbounded
from torchrl.envs.model_based import ModelBasedEnvBase
from torchrl.modules import WorldModelWrapper

from kinet_rl.keys import ACTION, KP_POS


class _AddPush(nn.Module):
    def forward(self, pos: Tensor, action: Tensor) -> Tensor:
        return pos + action.reshape(pos.shape)


class _NegSquaredDistance(nn.Module):
    def __init__(self, goal: Tensor) -> None:
        super().__init__()
        self.register_buffer("goal", goal)

    def forward(self, pos: Tensor) -> Tensor:
        return -(pos - self.goal).pow(2).sum((-2, -1)).unsqueeze(-1)


class QuadraticModelEnv(ModelBasedEnvBase):
    """Next ``pos = pos + a``, reward ``-|pos' - goal|^2``; positions [K, 2], action [2K] in [-1, 1]."""

    def __init__(self, goal: Tensor, start: Tensor | None = None) -> None:
        num_points = goal.shape[0]
        world_model = WorldModelWrapper(
            TensorDictModule(_AddPush(), in_keys=[KP_POS, ACTION], out_keys=[KP_POS]),
            TensorDictModule(_NegSquaredDistance(goal), in_keys=[KP_POS], out_keys=["reward"]),
        )
        super().__init__(world_model)
        self.start = torch.zeros(num_points, 2) if start is None else start
        pos_spec = Unbounded((num_points, 2))
        self.observation_spec = Composite({KP_POS: pos_spec})
        self.state_spec = Composite({KP_POS: pos_spec.clone()})
        self.action_spec = Bounded(-1.0, 1.0, (2 * num_points,))
        self.reward_spec = Unbounded((1,))

    def _reset(self, tensordict: TensorDict | None, **kwargs) -> TensorDict:
        batch = () if tensordict is None else tensordict.batch_size
        pos = self.start.expand(*batch, *self.start.shape).clone()
        return TensorDict({KP_POS: pos}, batch_size=batch)


class _TrapStep(nn.Module):
    """1-d: s' = s + a; done once s' <= -0.5; reward s' before done, +10 after it."""

    def forward(self, pos: Tensor, action: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        nxt = pos + action
        already_done = pos <= -0.5
        reward = torch.where(already_done, torch.full_like(nxt, 10.0), nxt)
        done = nxt <= -0.5
        return nxt, reward, done


class TrapModelEnv(ModelBasedEnvBase):
    """An env where counting rewards after ``done`` favours the terminating direction."""

    def __init__(self) -> None:
        world_model = TensorDictModule(
            _TrapStep(), in_keys=["pos", ACTION], out_keys=["pos", "reward", "done"]
        )
        super().__init__(world_model)
        self.observation_spec = Composite(pos=Unbounded((1,)))
        self.state_spec = Composite(pos=Unbounded((1,)))
        self.action_spec = Bounded(-1.0, 1.0, (1,))
        self.reward_spec = Unbounded((1,))

    def _step(self, tensordict: TensorDict) -> TensorDict:
        out = super()._step(tensordict)
        out.set("terminated", out.get("done").clone())
        return out

    def _reset(self, tensordict: TensorDict | None, **kwargs) -> TensorDict:
        batch = () if tensordict is None else tensordict.batch_size
        return TensorDict({"pos": torch.zeros(*batch, 1)}, batch_size=batch)
