"""TorchRL transform that adds detected keypoints to an environment's observations."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict import NestedKey, TensorDictBase
from torchrl.data import Composite, Unbounded
from torchrl.envs.transforms import Transform

from kinet_rl.keys import KP_FEAT, KP_POS, PIXELS
from kinet_rl.models.keypoints import KeypointDetector


class KeypointTransform(Transform):
    """Runs a (frozen) :class:`KeypointDetector` on image observations.

    The detector runs without gradient; its parameters are not trained through the transform.

    Keys:
        Reads ``in_keys[0]`` (default ``"pixels"``, ``[*B, H, W, 3]``). Writes ``out_keys``
        (default ``("keypoints", "pos")`` ``[*B, K, 2]`` in ``[-1, 1]`` (x right, y down) and
        ``("keypoints", "feat")`` ``[*B, K, D]``), and adds both to the observation spec.

    Args:
        detector: The keypoint detector.
        in_keys: One image key.
        out_keys: Position and feature keys.
    """

    def __init__(
        self,
        detector: KeypointDetector,
        in_keys: Sequence[NestedKey] = (PIXELS,),
        out_keys: Sequence[NestedKey] = (KP_POS, KP_FEAT),
    ) -> None:
        if len(in_keys) != 1 or len(out_keys) != 2:
            raise ValueError(
                "KeypointTransform takes one image in_key and two out_keys (positions, features); "
                f"got in_keys={list(in_keys)}, out_keys={list(out_keys)}."
            )
        super().__init__(in_keys=list(in_keys), out_keys=list(out_keys))
        self.detector = detector

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        pixels = next_tensordict.get(self.in_keys[0], None)
        if pixels is None:
            raise KeyError(
                f"KeypointTransform found no image at {self.in_keys[0]!r}; create the env with "
                "pixel observations or pass in_keys= naming the image entry."
            )
        with torch.no_grad():
            pos, feat = self.detector(pixels)
        next_tensordict.set(self.out_keys[0], pos)
        next_tensordict.set(self.out_keys[1], feat)
        return next_tensordict

    def _reset(
        self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase
    ) -> TensorDictBase:
        return self._call(tensordict_reset)

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        """Adds the keypoint position and feature specs (float32, unbounded)."""
        if self.in_keys[0] not in observation_spec.keys(True):
            raise KeyError(
                f"KeypointTransform found no image spec at {self.in_keys[0]!r} (observations: "
                f"{list(observation_spec.keys(True, True))}); create the env with pixel "
                "observations or pass in_keys= naming the image entry."
            )
        image_spec = observation_spec[self.in_keys[0]]
        batch = image_spec.shape[:-3]
        k, d = self.detector.num_keypoints, self.detector.feat_dim
        device = image_spec.device
        observation_spec[self.out_keys[0]] = Unbounded(
            shape=(*batch, k, 2), dtype=torch.float32, device=device
        )
        observation_spec[self.out_keys[1]] = Unbounded(
            shape=(*batch, k, d), dtype=torch.float32, device=device
        )
        return observation_spec
