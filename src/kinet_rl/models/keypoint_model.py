"""What a world model on detected keypoints shares: rendering, evaluation read-outs, its rollout.

KINet and the V-CDN baseline both see the scene through a :class:`KeypointDetector` trained with a
:class:`KeypointReconstructor`, and predict how the keypoints move under pushes. This base turns
their keypoint rollout into the forward-prediction read-outs of the evaluation (objects follow
their keypoints, :mod:`kinet_rl.models.object_rollout`) and renders predicted frames.
"""

from __future__ import annotations

from typing import ClassVar

import torch
from torch import Tensor, nn

from kinet_rl.envs.geometry import SceneGeometry
from kinet_rl.models.keypoints import KeypointDetector, KeypointReconstructor
from kinet_rl.models.object_rollout import DetectorFloor, KeypointObjectRollout


class KeypointWorldModel(nn.Module):
    """A world model whose state is the keypoints of ``detector`` (reconstructed by ``reconstructor``).

    Subclasses build ``detector`` and ``reconstructor``, name themselves in ``label`` and
    implement :meth:`rollout_keypoints`.
    """

    label: ClassVar[str]
    detector: KeypointDetector
    reconstructor: KeypointReconstructor

    def rollout_keypoints(self, pixels: Tensor, actions: Tensor) -> Tensor:
        """Open-loop keypoint rollout from first frames (no gradient).

        Args:
            pixels: ``[B, H, W, 3]`` frames where prediction starts.
            actions: ``[B, L, 4]`` pushes.

        Returns:
            ``[B, L + 1, K, 2]`` keypoints: detected at step 0, predicted after.
        """
        raise NotImplementedError(f"{type(self).__name__} must implement rollout_keypoints.")

    @torch.no_grad()
    def predict_pixels(self, pixels_0: Tensor, pos: Tensor) -> Tensor:
        """Renders images ``f_rec(I_0, x_0, pos)``, e.g. the predicted future frame.

        Args:
            pixels_0: ``[B, H, W, 3]`` initial frames.
            pos: ``[B, K, 2]`` keypoints of the frames to render (e.g. ``("next", KP_POS)``).

        Returns:
            ``[B, H, W, 3]`` float images in ``[0, 1]``.
        """
        source = self.detector.encode(pixels_0)
        return (self.reconstructor.render(source, pos) + 0.5).clamp(0.0, 1.0)

    def object_rollout(self, geometry: SceneGeometry) -> KeypointObjectRollout:
        """Object positions read off predicted keypoints, for forward-prediction evaluation."""
        return KeypointObjectRollout(self, geometry)

    def detector_floor(self, geometry: SceneGeometry) -> DetectorFloor:
        """Object positions read off keypoints detected in the true frames (Table I's floor)."""
        return DetectorFloor(self, geometry)
