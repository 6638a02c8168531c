"""A TorchRL model env over a state that travels in the tensordict, for any world model.

Model envs of world models (KINet's, the baselines', the oracle's analytic push model) differ only
in their step module and their state entries; :class:`StateModelEnv` holds what they share: a full
state spec, the 4-d push action in ``[-1, 1]``, a ``[*B, 1]`` reward, no batch lock, and a reset
that passes a given state through.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
from tensordict import NestedKey, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torch import Tensor
from torchrl.data import Bounded, Composite, Unbounded
from torchrl.envs.model_based import ModelBasedEnvBase

#: Dimension of the push action (start x, start y, end x, end y).
ACTION_DIM = 4


def check_goal_image(pixels: Tensor, goal_pixels: Tensor) -> None:
    """Raises a ValueError unless current and goal images ``[*B, H, W, 3]`` share ``[H, W, 3]``."""
    if goal_pixels.shape[-3:] != pixels.shape[-3:]:
        raise ValueError(
            f"goal image {tuple(goal_pixels.shape[-3:])} and current image "
            f"{tuple(pixels.shape[-3:])} must have the same [H, W, 3]; resize the goal image."
        )


class StateModelEnv(ModelBasedEnvBase):
    """Imagined steps of ``step`` on the state entries ``state_shapes``.

    The step module reads the state entries and ``ACTION`` and writes the next state entries and
    ``STEP_REWARD`` (``[*B, 1]``). The state (including the goal, so that every batch element may
    have its own) is given to :meth:`reset`; subclasses build it from observations in ``observe``.

    Args:
        step: TensorDict module of one imagined step.
        state_shapes: Per-element shape of every state entry.
        device: Device of the state (default: that of the step's parameters, else CPU).
        reset_hint: What to tell a caller whose reset tensordict lacks the state.
    """

    def __init__(
        self,
        step: TensorDictModuleBase,
        state_shapes: Mapping[NestedKey, tuple[int, ...]],
        device: torch.device | str | None = None,
        reset_hint: str = "env.observe(...) builds it from an observation and a goal.",
    ) -> None:
        if device is None:
            device = next(step.parameters(), torch.empty(0)).device
        super().__init__(step, device=device, batch_size=torch.Size([]))
        state = Composite(
            {key: Unbounded(shape, device=device) for key, shape in state_shapes.items()},
            device=device,
        )
        self.observation_spec = state.clone()
        self.state_spec = state
        self.action_spec = Bounded(-1.0, 1.0, (ACTION_DIM,), device=device)
        self.reward_spec = Unbounded((1,), device=device)
        self.reset_hint = reset_hint

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        keys = list(self.state_spec.keys(True, True))
        if tensordict is None or any(key not in tensordict.keys(True) for key in keys):
            raise KeyError(
                f"{type(self).__name__}.reset needs a tensordict with the state keys {keys}; "
                f"{self.reset_hint}"
            )
        return tensordict.select(*keys).clone()
