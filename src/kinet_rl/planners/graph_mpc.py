"""GraphMPC: sampling-based MPC (CEM or MPPI) over any non-batch-locked TorchRL model env."""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from typing import Any

import torch
from tensordict import NestedKey, TensorDictBase
from torch import Tensor
from torchrl.data import Bounded, Unbounded
from torchrl.envs import EnvBase
from torchrl.modules.planners import MPCPlannerBase

from kinet_rl.config_schema import check_arguments, require
from kinet_rl.keys import ACTION, REWARD

logger = logging.getLogger(__name__)

UPDATE_RULES = ("cem", "mppi")
#: :class:`GraphMPCPlanner` arguments that code passes, not planner settings.
CODE_ARGUMENTS = ("env", "reward_key", "action_key", "generator")
IS_INIT = "is_init"  # written by torchrl's InitTracker transform


class GraphMPCPlanner(MPCPlannerBase):
    """Plans an action by sampling action sequences and scoring imagined rollouts of a model env.

    Each call samples ``num_candidates`` action sequences of length ``planning_horizon`` from a
    diagonal Gaussian, rolls all of them out in one batched loop through ``env`` (any env with
    ``batch_locked=False``, e.g. a :class:`~torchrl.envs.model_based.ModelBasedEnvBase`), scores
    each by the sum of ``reward_key`` over the horizon (rewards after the first ``done`` are not
    counted) and refits the Gaussian to the ``top_k`` elites, ``optim_steps`` times. The first
    action of the final mean is returned, or with ``return_best`` that of the best sequence
    scored in any iteration (the elite mean can average pushes of different modes into one that
    touches nothing). With ``keep_elites`` > 0 the best sequences of an iteration are scored again
    in the next instead of as many fresh samples (iCEM, Pinneri et al. 2020).

    Update rules:
        ``"cem"``: elites weighted equally (cross-entropy method).
        ``"mppi"``: elites weighted by ``exp(temperature * (return - max_return))``, normalised,
        as in TD-MPC2 and torchrl's ``MPPIPlanner`` (``temperature`` multiplies the return, so a
        larger value is greedier).

    The standard deviation is clamped to ``[min_std, max_std]``; each call starts from
    ``std = max_std``. With ``warm_start=True`` the mean starts from the previous call's plan
    shifted by one step (the last step starts at the centre of the action bounds). The plan is
    kept per batch element: :meth:`reset` clears it (all or a mask), an ``"is_init"`` entry
    (torchrl's ``InitTracker``) in the input clears it for the flagged elements, and a change of
    batch shape clears it entirely. Sampled actions are clamped to the action spec bounds.

    Random numbers come from ``generator`` when given, else from the global torch RNG, so a
    fixed ``torch.manual_seed`` gives the same plan. A sequence of generators, one per element of
    the first batch dim, draws each element's samples from its own generator: a batch of episodes
    planned in one call then samples exactly what each would alone (batched evaluation).

    Reference: KINet, Rezazadeh et al., RA-L 2023 (GraphMPC, Sec. 3.4); TD-MPC2, Hansen et al.,
    ICLR 2024 (MPPI update, warm start).

    Keys:
        Reads the input tensordict (``[*B]``) as the env's start state; the env sees it as a
        broadcast view ``[*B, N]`` (stride 0 over the candidates, so the env must not write its
        entries in place), from which it may compute what does not depend on the action once
        (KINet's world model does). Writes ``action_key`` ``[*B, *A]``.

    Args:
        env: Model env with ``batch_locked=False`` and a continuous action spec.
        planning_horizon: Steps per imagined rollout (T).
        optim_steps: Refit iterations per call.
        num_candidates: Sampled action sequences per iteration (N).
        top_k: Elites used to refit the Gaussian.
        update_rule: ``"cem"`` or ``"mppi"``.
        temperature: MPPI weight scale; ignored by CEM.
        min_std: Floor of the sampling standard deviation.
        max_std: Ceiling of the sampling standard deviation, and its value at the first iteration.
        warm_start: Start from the previous plan shifted by one step.
        return_best: Return (and warm-start from) the best sequence scored instead of the mean.
        keep_elites: Elites carried into the next iteration's candidates (0: none).
        reward_key: Reward read after each imagined step.
        action_key: Where the planned action is written.
        generator: Optional RNG for sampling, or one per element of the first batch dim.
    """

    def __init__(
        self,
        env: EnvBase,
        planning_horizon: int = 3,
        optim_steps: int = 5,
        num_candidates: int = 256,
        top_k: int = 32,
        update_rule: str = "cem",
        temperature: float = 0.5,
        min_std: float = 0.05,
        max_std: float = 1.0,
        warm_start: bool = True,
        return_best: bool = False,
        keep_elites: int = 0,
        reward_key: NestedKey = REWARD,
        action_key: NestedKey = ACTION,
        generator: torch.Generator | Sequence[torch.Generator] | None = None,
    ) -> None:
        _check_arguments(
            planning_horizon=planning_horizon,
            optim_steps=optim_steps,
            num_candidates=num_candidates,
            top_k=top_k,
            update_rule=update_rule,
            temperature=temperature,
            min_std=min_std,
            max_std=max_std,
            keep_elites=keep_elites,
        )
        super().__init__(env=env, action_key=action_key)
        self.planning_horizon = planning_horizon
        self.optim_steps = optim_steps
        self.num_candidates = num_candidates
        self.top_k = top_k
        self.update_rule = update_rule
        self.temperature = temperature
        self.min_std = min_std
        self.max_std = max_std
        self.warm_start = warm_start
        self.return_best = return_best
        self.keep_elites = keep_elites
        self.reward_key = reward_key
        self.generator = generator
        self._env_action_key = env.action_key
        self._done_keys = [
            ("next", *_as_tuple(key)) for key in env.done_keys if _as_tuple(key)[-1] == "done"
        ]
        self._action_shape = env.action_spec.shape[len(env.batch_size) :]
        self._low, self._high, self._centre = _action_bounds(env, self._action_shape)
        self._prev_mean: Tensor | None = None  # [*B, T, *A]

    @property
    def plan(self) -> Tensor | None:
        """The last optimised plan ``[*B, T, *A]`` (warm-start source), or None after a reset."""
        return self._prev_mean

    def reset(self, mask: Tensor | None = None) -> None:
        """Forgets the warm-start plan, for all batch elements or only where ``mask`` is True."""
        if mask is None or self._prev_mean is None:
            self._prev_mean = None
            return
        batch_shape = self._prev_mean.shape[: -1 - len(self._action_shape)]
        mask = self._plan_mask(mask.to(self._prev_mean.device), batch_shape)
        self._prev_mean = torch.where(mask, self._centre.to(self._prev_mean), self._prev_mean)

    @torch.no_grad()
    def planning(self, tensordict: TensorDictBase) -> Tensor:
        """Returns the first action of the optimised plan, ``[*B, *A]``."""
        batch_shape = tensordict.batch_size
        mean = self._initial_mean(tensordict)  # [*B, 1, T, *A]
        std = torch.full_like(mean, self.max_std)
        # [*B, N] views (stride 0 over N): a model env can tell that every candidate starts from
        # the same state and compute what does not depend on the action once.
        start = tensordict.exclude("next").unsqueeze(-1).expand(*batch_shape, self.num_candidates)
        n_event = 1 + len(self._action_shape)  # T and action dims
        dim = len(batch_shape)  # the candidate dim
        kept: Tensor | None = None  # [*B, keep, T, *A] elites carried over (iCEM)
        best_return = torch.full(batch_shape, -math.inf, device=mean.device, dtype=mean.dtype)
        best = mean.squeeze(dim)  # [*B, T, *A] best sequence scored (return_best only)
        for _ in range(self.optim_steps):
            noise = self._noise((*batch_shape, self.num_candidates, *mean.shape[-n_event:]), mean)
            actions = self._clamp(mean + std * noise)  # [*B, N, T, *A]
            if kept is not None:
                actions = torch.cat(
                    [
                        kept,
                        actions.narrow(dim, kept.shape[dim], self.num_candidates - kept.shape[dim]),
                    ],
                    dim,
                )
            returns = self.rollout_returns(start, actions)  # [*B, N]
            weights, elite_idx = self._elite_weights(returns)  # [*B, k]
            index = elite_idx.reshape(*elite_idx.shape, *([1] * n_event))
            index = index.expand(*elite_idx.shape, *mean.shape[-n_event:])
            elites = actions.gather(dim, index)  # [*B, k, T, *A], best first
            if self.keep_elites:
                kept = elites.narrow(dim, 0, self.keep_elites)
            if self.return_best:
                top = returns.gather(-1, elite_idx.narrow(-1, 0, 1)).squeeze(-1)  # [*B]
                better = (top > best_return).reshape(*batch_shape, *([1] * n_event))
                best = torch.where(better, elites.select(dim, 0), best)
                best_return = torch.maximum(best_return, top)
            weights = weights.reshape(*elite_idx.shape, *([1] * n_event))
            mean = (weights * elites).sum(dim, keepdim=True)
            var = (weights * (elites - mean).pow(2)).sum(dim, keepdim=True)
            std = var.sqrt().clamp(self.min_std, self.max_std)
        plan = best if self.return_best else mean.squeeze(dim)  # [*B, T, *A]
        self._prev_mean = plan.clone()
        return plan.select(dim, 0)

    def rollout_returns(self, start: TensorDictBase, actions: Tensor) -> Tensor:
        """Sums rewards of imagined rollouts, ignoring rewards after the first ``done``.

        Args:
            start: Start states, batch ``[*B, N]``; not modified.
            actions: ``[*B, N, T, *A]`` action sequences.

        Returns:
            ``[*B, N]`` returns.
        """
        batch_shape = start.batch_size
        time_dim = len(batch_shape)
        returns = torch.zeros(batch_shape, device=actions.device, dtype=actions.dtype)
        alive = torch.ones(batch_shape, device=actions.device, dtype=torch.bool)
        state = start.copy()
        for t in range(actions.shape[time_dim]):
            state.set(self._env_action_key, actions.select(time_dim, t))
            state = self.env.step(state)
            reward = state.get(self.reward_key, None)
            if reward is None:
                raise KeyError(
                    f"The env did not write the reward key {self.reward_key!r}; pass the "
                    f"planner's reward_key= one of the env's reward keys ({self.env.reward_keys})."
                )
            reward = reward.reshape(*batch_shape, -1).sum(-1)
            returns = returns + torch.where(alive, reward.to(returns.dtype), 0.0)
            for key in self._done_keys:
                alive = alive & ~state.get(key).reshape(*batch_shape, -1).any(-1)
            state = self.env.step_mdp(state)
        return torch.nan_to_num(returns, nan=-math.inf)

    def _initial_mean(self, tensordict: TensorDictBase) -> Tensor:
        """Starting mean ``[*B, 1, T, *A]``: centre of the bounds, or the shifted previous plan."""
        batch_shape = tensordict.batch_size
        plan_shape = (*batch_shape, self.planning_horizon, *self._action_shape)
        centre = self._centre.to(tensordict.device).expand(plan_shape)
        prev = self._prev_mean
        if not self.warm_start or prev is None:
            mean = centre.clone()
        elif prev.shape != plan_shape:
            logger.info(
                "GraphMPCPlanner: batch shape changed from %s to %s; warm start cleared.",
                tuple(prev.shape[: -1 - len(self._action_shape)]),
                tuple(batch_shape),
            )
            mean = centre.clone()
        else:
            time_dim = len(batch_shape)
            shifted = prev.narrow(time_dim, 1, self.planning_horizon - 1)
            mean = torch.cat([shifted, centre.narrow(time_dim, 0, 1)], dim=time_dim)
            is_init = tensordict.get(IS_INIT, None)
            if is_init is not None:
                mean = torch.where(self._plan_mask(is_init, batch_shape), centre, mean)
        return mean.unsqueeze(len(batch_shape))

    def _noise(self, shape: tuple[int, ...], like: Tensor) -> Tensor:
        """Standard normal samples of ``shape``, from the generator(s) (see the class docstring)."""
        generators = self.generator
        if generators is None or isinstance(generators, torch.Generator):
            return torch.randn(shape, generator=generators, device=like.device, dtype=like.dtype)
        batch = shape[: len(shape) - 2 - len(self._action_shape)]
        if not batch or batch[0] != len(generators):
            raise ValueError(
                f"GraphMPCPlanner has {len(generators)} generators (one per element of the first "
                f"batch dim) but was called with batch {tuple(batch)}; plan a batch of "
                f"{len(generators)} or pass one generator."
            )
        return torch.stack(
            [
                torch.randn(shape[1:], generator=g, device=like.device, dtype=like.dtype)
                for g in generators
            ]
        )

    def _plan_mask(self, mask: Tensor, batch_shape: torch.Size) -> Tensor:
        """Reduces a ``[*B]`` or ``[*B, 1]`` flag to ``[*B, 1, ...]`` broadcastable to a plan."""
        mask = mask.reshape(*batch_shape, -1).any(-1)
        return mask.reshape(*batch_shape, *([1] * (1 + len(self._action_shape))))

    def _elite_weights(self, returns: Tensor) -> tuple[Tensor, Tensor]:
        """Elite indices ``[*B, k]`` into the candidate dim and their weights (sum to 1)."""
        elite_returns, elite_idx = returns.topk(self.top_k, dim=-1)
        if self.update_rule == "cem":
            weights = torch.full_like(elite_returns, 1.0 / self.top_k)
        else:
            shifted = elite_returns - elite_returns.max(-1, keepdim=True).values
            weights = torch.exp(self.temperature * torch.nan_to_num(shifted, nan=-math.inf))
            weights = weights / weights.sum(-1, keepdim=True)
        # All candidates invalid (-inf): fall back to equal weights rather than NaN.
        weights = torch.nan_to_num(weights, nan=1.0 / self.top_k)
        return weights, elite_idx

    def _clamp(self, actions: Tensor) -> Tensor:
        if self._low is None or self._high is None:
            return actions
        return torch.maximum(torch.minimum(actions, self._high.to(actions)), self._low.to(actions))


def _action_bounds(
    env: EnvBase, action_shape: torch.Size
) -> tuple[Tensor | None, Tensor | None, Tensor]:
    """Returns (low, high, centre) of a continuous action spec, each of ``action_shape``."""
    spec = env.action_spec
    if not spec.dtype.is_floating_point:
        raise TypeError(
            f"GraphMPCPlanner samples Gaussian actions and needs a floating-point action spec; "
            f"got dtype {spec.dtype}. Use a continuous (Bounded/Unbounded float) action spec."
        )
    if isinstance(spec, Bounded):
        n_batch = len(env.batch_size)
        index = (0,) * n_batch
        low = spec.low[index].clone() if n_batch else spec.low.clone()
        high = spec.high[index].clone() if n_batch else spec.high.clone()
        return low, high, (low + high) / 2
    if isinstance(spec, Unbounded):
        return None, None, torch.zeros(action_shape, dtype=spec.dtype, device=spec.device)
    raise TypeError(
        f"GraphMPCPlanner needs a Bounded or Unbounded action spec, got {type(spec).__name__}."
    )


def _as_tuple(key: NestedKey) -> tuple[str, ...]:
    return (key,) if isinstance(key, str) else tuple(key)


def check_planner_settings(settings: Mapping[str, Any]) -> None:
    """Checks :class:`GraphMPCPlanner` keyword arguments (a ``planner`` config) without an env.

    Raises:
        ConfigError: An unknown key, a wrong type or a value the planner refuses (e.g.
            ``top_k > num_candidates``), named.
    """
    _check_arguments(**check_arguments(GraphMPCPlanner, settings, exclude=CODE_ARGUMENTS))


def _check_arguments(
    *,
    planning_horizon: int,
    optim_steps: int,
    num_candidates: int,
    top_k: int,
    update_rule: str,
    temperature: float,
    min_std: float,
    max_std: float,
    keep_elites: int,
    **_: Any,
) -> None:
    for name, value in (
        ("planning_horizon", planning_horizon),
        ("optim_steps", optim_steps),
        ("num_candidates", num_candidates),
        ("top_k", top_k),
    ):
        require(int(value) == value and value >= 1, name, value, "a positive integer")
    require(
        top_k <= num_candidates,
        "top_k",
        top_k,
        f"at most num_candidates={num_candidates}",
    )
    require(update_rule in UPDATE_RULES, "update_rule", update_rule, f"one of {UPDATE_RULES}")
    require(temperature > 0, "temperature", temperature, "a number > 0")
    require(0 < min_std <= max_std, "min_std", min_std, f"in (0, max_std={max_std}]")
    require(
        0 <= keep_elites <= min(top_k, num_candidates - 1),
        "keep_elites",
        keep_elites,
        "an integer in [0, min(top_k, num_candidates - 1)]",
    )
