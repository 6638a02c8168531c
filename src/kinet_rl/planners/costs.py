"""Goal rewards for planning: keypoint distance and graph-embedding similarity.

The reward functions take tensors; :class:`GoalReward` attaches one to an env as a torchrl
transform that reads a goal stored in the tensordict and writes ``("next", "reward")``.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from tensordict import NestedKey, TensorDictBase
from torch import Tensor
from torchrl.data import Composite, Unbounded
from torchrl.envs.transforms import Transform

from kinet_rl.keys import GOAL_KP_POS, KP_POS, STEP_REWARD

RewardFn = Callable[[Tensor, Tensor], Tensor]


def keypoint_goal_reward(pos: Tensor, goal_pos: Tensor) -> Tensor:
    """Negative sum over points of squared distances to the goal positions.

    Args:
        pos: ``[*B, K, 2]`` keypoint (or object) positions.
        goal_pos: ``[*B, K, 2]`` goal positions (broadcastable to ``pos``).

    Returns:
        ``[*B, 1]`` reward, 0 at the goal and negative elsewhere.
    """
    _check_same_trailing_shape(pos, goal_pos, "pos", "goal_pos")
    return -(pos - goal_pos).pow(2).sum(dim=(-2, -1)).unsqueeze(-1)


def graph_similarity_reward(node_emb: Tensor, goal_node_emb: Tensor) -> Tensor:
    """Graph similarity ``S(G, G_goal) = sum_k n_k . n_goal_k`` of node embeddings.

    Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 3.3-3.4 (graph matching, GraphMPC).

    Args:
        node_emb: ``[*B, K, D]`` node embeddings of the (predicted) graph.
        goal_node_emb: ``[*B, K, D]`` node embeddings of the goal graph (broadcastable).

    Returns:
        ``[*B, 1]`` similarity; larger is closer to the goal.
    """
    _check_same_trailing_shape(node_emb, goal_node_emb, "node_emb", "goal_node_emb")
    return (node_emb * goal_node_emb).sum(dim=(-2, -1)).unsqueeze(-1)


class GoalReward(Transform):
    """Writes a goal-conditioned reward computed from an observation and a goal in the tensordict.

    The goal is read from the input tensordict (or ``default_goal``) at reset and at every step,
    and copied into ``"next"`` so it is carried along rollouts and imagined planner rollouts.
    The goal entry (same shape as ``in_key``) is added to the observation and state specs, so
    ``env.reset(TensorDict({goal_key: goal}))`` sets it; the reward spec becomes an unbounded
    ``[*B, 1]`` float.

    Keys:
        Reads ``in_key`` (e.g. ``("keypoints", "pos")`` ``[*B, K, 2]``) from ``"next"`` and
        ``goal_key`` (same shape) from the root or ``"next"``. Writes ``("next", reward_key)``
        ``[*B, 1]`` and ``("next", goal_key)``.

    Args:
        reward_fn: ``reward_fn(obs, goal) -> [*B, 1]``, e.g. :func:`keypoint_goal_reward` or
            :func:`graph_similarity_reward`.
        in_key: Observation the reward is computed from.
        goal_key: Goal entry, same shape as ``in_key``.
        reward_key: Reward entry written under ``"next"``.
        default_goal: Goal used when a reset tensordict carries none (broadcast to the batch).
    """

    def __init__(
        self,
        reward_fn: RewardFn = keypoint_goal_reward,
        in_key: NestedKey = KP_POS,
        goal_key: NestedKey = GOAL_KP_POS,
        reward_key: NestedKey = STEP_REWARD,
        default_goal: Tensor | None = None,
    ) -> None:
        super().__init__(in_keys=[in_key, goal_key], out_keys=[reward_key])
        self.reward_fn = reward_fn
        self.in_key = in_key
        self.goal_key = goal_key
        self.reward_key = reward_key
        self.default_goal = default_goal

    def _goal(self, *sources: TensorDictBase) -> Tensor:
        """The goal from the first source that has one, else ``default_goal`` for the last's batch."""
        for source in sources:
            if (goal := source.get(self.goal_key, None)) is not None:
                return goal
        if self.default_goal is None:
            raise KeyError(
                f"GoalReward found no goal at {self.goal_key!r}: put the goal in the tensordict "
                f"passed to env.reset()/the planner, or pass default_goal= to GoalReward."
            )
        ref = sources[-1]
        goal = self.default_goal if ref.device is None else self.default_goal.to(ref.device)
        return goal.expand(*ref.batch_size, *goal.shape[-2:]).clone()

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        next_tensordict.set(self.goal_key, self._goal(next_tensordict, tensordict))
        return self._call(next_tensordict)

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        goal = self._goal(next_tensordict)
        obs = next_tensordict.get(self.in_key, None)
        if obs is None:
            raise KeyError(f"GoalReward: no {self.in_key!r} in the step output to score.")
        next_tensordict.set(self.reward_key, self.reward_fn(obs, goal))
        return next_tensordict

    def _reset(
        self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase
    ) -> TensorDictBase:
        goal = self._goal(tensordict_reset, tensordict, tensordict_reset)
        tensordict_reset.set(self.goal_key, goal)
        return tensordict_reset

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        observation_spec.set(self.goal_key, self._goal_spec(observation_spec))
        return observation_spec

    def transform_state_spec(self, state_spec: Composite) -> Composite:
        # A state entry, so that env.reset(td) passes the goal through to the transform.
        state_spec.set(self.goal_key, self._goal_spec(self.parent.full_observation_spec))
        return state_spec

    def _goal_spec(self, observation_spec: Composite) -> Unbounded:
        in_spec = observation_spec.get(self.in_key, None)
        if in_spec is None:
            raise KeyError(
                f"GoalReward: in_key {self.in_key!r} is not in the observation spec "
                f"({list(observation_spec.keys(True, True))}); pass an existing in_key."
            )
        return Unbounded(shape=in_spec.shape, dtype=in_spec.dtype, device=in_spec.device)

    def transform_reward_spec(self, reward_spec: Composite) -> Composite:
        batch = self.parent.batch_size if self.parent is not None else reward_spec.shape
        reward_spec.set(
            self.reward_key,
            Unbounded(shape=(*batch, 1), dtype=torch.float32, device=reward_spec.device),
        )
        return reward_spec


def _check_same_trailing_shape(x: Tensor, goal: Tensor, x_name: str, goal_name: str) -> None:
    if x.shape[-2:] != goal.shape[-2:]:
        raise ValueError(
            f"{x_name} has per-item shape {tuple(x.shape[-2:])} but {goal_name} has "
            f"{tuple(goal.shape[-2:])}; they must match ([K, 2] positions or [K, D] embeddings)."
        )
