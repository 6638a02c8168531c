"""The baselines as ``torchrl.modules.WorldModel``s (encoder, one-push dynamics, goal reward).

"For all baseline models, we perform MPC directly on the distance to the goal" (KINet, Sec. 5):

* IN / IN-full / VisIN (:func:`object_world_model`): state = ground-truth object positions (+ the
  model's node features of the current state: IN-full's yaw and shape, VisIN's crop features of
  the current image, carried over while imagining); objective ``object_distance`` (metres).
* Forw / ForwInv (:func:`feature_world_model`): state = the whole-image feature ``z``; objective
  ``feature_distance`` to the goal image's feature.
* V-CDN (:func:`vcdn_world_model`): state = the detected keypoints and the graph inferred from
  them (carried over while imagining); objective ``keypoints_distance`` to the goal image's
  keypoints (index-matched, image units).

The builders take the model's parts by duck typing, so the model classes (which call them from
their ``world_model`` method) are not imported here.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from tensordict import NestedKey, TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torch import Tensor, nn

from kinet_rl.keys import (
    ACTION,
    GOAL_IMAGE_FEAT,
    GOAL_KP_POS,
    GOAL_OBJECT_POS,
    GOAL_PIXELS,
    IMAGE_FEAT,
    KP_EDGE_TYPE,
    KP_POS,
    OBJECT_FEAT,
    OBJECT_POS,
    PIXELS,
)
from kinet_rl.models.imagination import check_goal_image
from kinet_rl.planners.objectives import goal_reward_head
from kinet_rl.planners.world_model import PushWorldModel, push_dynamics


class _Encoder(TensorDictModuleBase):
    """An encoder from a function ``tensordict -> {key: tensor}`` (eval mode, no gradient)."""

    def __init__(
        self,
        model: nn.Module,
        encode: Callable[[TensorDictBase], dict[NestedKey, Tensor]],
        in_keys: list[NestedKey],
        out_keys: list[NestedKey],
    ) -> None:
        super().__init__()
        self.model = model  # holds the parameters that ``encode`` uses
        self.encode = encode
        self.in_keys = in_keys
        self.out_keys = out_keys

    @torch.no_grad()
    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        self.model.eval()
        for key, value in self.encode(tensordict).items():
            tensordict.set(key, value)
        return tensordict


class _CarriedContext(nn.Module):
    """``predict(pos, context, action)`` with the context carried to the next state."""

    def __init__(self, model: nn.Module, predict: Callable[[Tensor, Tensor, Tensor], Tensor]):
        super().__init__()
        self.model = model  # holds the parameters that ``predict`` uses
        self.predict = predict

    def forward(self, pos: Tensor, context: Tensor, action: Tensor) -> tuple[Tensor, Tensor]:
        return self.predict(pos, context, action), context


class _FeatureStep(nn.Module):
    def __init__(self, model: nn.Module) -> None:
        super().__init__()
        self.model = model

    def forward(self, feat: Tensor, action: Tensor) -> tuple[Tensor]:
        return (self.model.predict(feat, action),)


def _device(model: nn.Module) -> torch.device:
    return next(model.parameters(), torch.empty(0)).device


def object_world_model(model, objective: str) -> PushWorldModel:
    """IN, IN-full or VisIN on ground-truth object positions.

    Keys:
        Encoder: ``OBJECT_POS`` ``[*B, N, 2]`` metres, the model's ``state_keys`` (IN-full:
        ``object_yaw``, ``object_shape``), ``PIXELS`` (VisIN) and ``GOAL_OBJECT_POS``
        ``[*B, N, 2]`` (or ``[N, 2]`` for all) in. State: ``OBJECT_POS``, ``OBJECT_FEAT``
        ``[*B, N, F]`` (``F = 0`` for IN), ``GOAL_OBJECT_POS``.
    """
    observes = [key for key in model.capabilities.observes if key != OBJECT_POS]

    def encode(td: TensorDictBase) -> dict[NestedKey, Tensor]:
        device = _device(model)
        object_pos = td.get(OBJECT_POS).to(device).float()
        batch = object_pos.shape[:-2]
        entries = {OBJECT_POS: object_pos}
        entries.update({key: td.get(key).to(device) for key in observes if key == PIXELS})
        entries.update({key: td.get(key).to(device).float() for key in model.state_keys})
        flat = TensorDict(
            {key: value.reshape(-1, *value.shape[len(batch) :]) for key, value in entries.items()},
            batch_size=[batch.numel()],
        )
        feat = model.node_features(flat).reshape(*batch, *object_pos.shape[-2:-1], -1)
        goal = td.get(GOAL_OBJECT_POS).to(device).float().expand_as(object_pos)
        return {OBJECT_POS: object_pos, OBJECT_FEAT: feat, GOAL_OBJECT_POS: goal}

    n, f = model.num_objects, model.node_feature_dim
    return PushWorldModel(
        _Encoder(
            model,
            encode,
            [*model.capabilities.observes, GOAL_OBJECT_POS],
            [OBJECT_POS, OBJECT_FEAT, GOAL_OBJECT_POS],
        ),
        push_dynamics(
            _CarriedContext(model, model.predict),
            [OBJECT_POS, OBJECT_FEAT, ACTION],
            [OBJECT_POS, OBJECT_FEAT],
            [GOAL_OBJECT_POS],
        ),
        goal_reward_head(objective),
        {OBJECT_POS: (n, 2), OBJECT_FEAT: (n, f), GOAL_OBJECT_POS: (n, 2)},
    )


def feature_world_model(model, objective: str) -> PushWorldModel:
    """Forw or ForwInv in the feature space of the whole image.

    Keys:
        Encoder: ``PIXELS`` ``[*B, H, W, 3]`` and ``GOAL_PIXELS`` in. State: ``IMAGE_FEAT``
        ``[*B, D]`` and ``GOAL_IMAGE_FEAT`` ``[*B, D]``.
    """

    def encode(td: TensorDictBase) -> dict[NestedKey, Tensor]:
        pixels, goal_pixels = td.get(PIXELS), td.get(GOAL_PIXELS)
        check_goal_image(pixels, goal_pixels)
        feat = model.encode(pixels.to(_device(model)))
        goal = model.encode(goal_pixels.to(_device(model))).expand_as(feat)
        return {IMAGE_FEAT: feat, GOAL_IMAGE_FEAT: goal}

    d = model.config["feature_dim"]
    return PushWorldModel(
        _Encoder(model, encode, [PIXELS, GOAL_PIXELS], [IMAGE_FEAT, GOAL_IMAGE_FEAT]),
        push_dynamics(_FeatureStep(model), [IMAGE_FEAT, ACTION], [IMAGE_FEAT], [GOAL_IMAGE_FEAT]),
        goal_reward_head(objective),
        {IMAGE_FEAT: (d,), GOAL_IMAGE_FEAT: (d,)},
    )


def vcdn_world_model(model, objective: str) -> PushWorldModel:
    """V-CDN on the keypoints of the current image and their inferred graph.

    Keys:
        Encoder: ``PIXELS`` and ``GOAL_PIXELS`` in. State: ``KP_POS`` ``[*B, K, 2]``,
        ``KP_EDGE_TYPE`` ``[*B, K, K - 1, C]`` (inferred from the current image's keypoints,
        carried over) and ``GOAL_KP_POS`` ``[*B, K, 2]`` (the goal image's keypoints; keypoint
        ``k`` against the goal's keypoint ``k``: the detector's channels are consistent).
    """

    def encode(td: TensorDictBase) -> dict[NestedKey, Tensor]:
        pixels, goal_pixels = td.get(PIXELS), td.get(GOAL_PIXELS)
        check_goal_image(pixels, goal_pixels)
        pos = model.keypoints(pixels.to(_device(model)))
        edge_types, _ = model.inference(pos)
        goal = model.keypoints(goal_pixels.to(_device(model))).expand_as(pos)
        return {KP_POS: pos, KP_EDGE_TYPE: edge_types, GOAL_KP_POS: goal}

    k, c = model.config["num_keypoints"], model.config["num_edge_types"]
    return PushWorldModel(
        _Encoder(model, encode, [PIXELS, GOAL_PIXELS], [KP_POS, KP_EDGE_TYPE, GOAL_KP_POS]),
        push_dynamics(
            _CarriedContext(model, model.dynamics),
            [KP_POS, KP_EDGE_TYPE, ACTION],
            [KP_POS, KP_EDGE_TYPE],
            [GOAL_KP_POS],
        ),
        goal_reward_head(objective),
        {KP_POS: (k, 2), KP_EDGE_TYPE: (k, k - 1, c), GOAL_KP_POS: (k, 2)},
    )
