"""Camera geometry: pinhole projection between the table and a camera's normalised image coordinates.

Image coordinates follow the keypoint convention of :mod:`kinet_rl.models.keypoints`: ``(x, y)``
in ``[-1, 1]``, x right, y down, ``-1``/``1`` at the image borders (``align_corners=False``).
Keypoints sit on object surfaces, not on the table, so points are lifted from or dropped onto the
horizontal plane at a typical object-centre height (:data:`OBJECT_CENTRE_HEIGHT`); for the top
camera the choice barely matters, for the angled side camera it is the main source of bias.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from kinet_rl.envs.blocks import BLOCK_HALF_HEIGHT
from kinet_rl.envs.factory import make_dm_env

#: Height (metres above the table top) at which object centres are taken to lie.
OBJECT_CENTRE_HEIGHT = {"blocks": BLOCK_HALF_HEIGHT, "ycb": 0.04}


@dataclass(frozen=True)
class CameraProjection:
    """A MuJoCo camera: position, orientation (columns: camera x, y, z in world) and field of view."""

    position: Tensor  # [3]
    rotation: Tensor  # [3, 3]
    tan_half_fovy: float

    @classmethod
    def from_physics(cls, physics, camera: str) -> CameraProjection:
        """Reads a camera of a dm_control physics (after ``forward``)."""
        cam_id = physics.model.name2id(camera, "camera")
        return cls(
            position=torch.as_tensor(np.array(physics.data.cam_xpos[cam_id]), dtype=torch.float32),
            rotation=torch.as_tensor(
                np.array(physics.data.cam_xmat[cam_id]).reshape(3, 3), dtype=torch.float32
            ),
            tan_half_fovy=float(np.tan(np.deg2rad(physics.model.cam_fovy[cam_id]) / 2.0)),
        )

    def to_image(self, xyz: Tensor) -> Tensor:
        """World points ``[*B, 3]`` -> normalised image coordinates ``[*B, 2]``."""
        local = (xyz - self.position) @ self.rotation  # camera frame: x right, y up, looks at -z
        depth = -local[..., 2:3]
        ndc = local[..., :2] / (depth * self.tan_half_fovy)
        return torch.stack([ndc[..., 0], -ndc[..., 1]], dim=-1)

    def to_plane(self, uv: Tensor, height: float) -> Tensor:
        """Normalised image coordinates ``[*B, 2]`` -> xy ``[*B, 2]`` on the plane ``z = height``."""
        ray_cam = torch.stack(
            [
                uv[..., 0] * self.tan_half_fovy,
                -uv[..., 1] * self.tan_half_fovy,
                -torch.ones_like(uv[..., 0]),
            ],
            dim=-1,
        )
        ray = ray_cam @ self.rotation.T
        t = (height - self.position[2]) / ray[..., 2:3]
        return (self.position + t * ray)[..., :2]

    def objects_to_image(self, object_xy: Tensor, height: float) -> Tensor:
        """Object positions ``[*B, N, 2]`` at ``height`` -> image coordinates ``[*B, N, 2]``."""
        z = torch.full_like(object_xy[..., :1], height)
        return self.to_image(torch.cat([object_xy, z], dim=-1))


def camera_projection(task: str, camera: str) -> CameraProjection:
    """The projection of a task's camera (builds the scene once to read it)."""
    env = make_dm_env(task=task, num_objects=1, camera=camera, image_size=16)
    try:
        env.physics.forward()
        return CameraProjection.from_physics(env.physics, camera)
    finally:
        env.close()


def normalised_to_pixels(uv: Tensor, image_size: int) -> Tensor:
    """Normalised image coordinates -> pixel coordinates (pixel centres at integers)."""
    return (uv + 1.0) * (image_size / 2.0) - 0.5


@dataclass(frozen=True)
class SceneGeometry:
    """How images relate to the table: the camera, the image size and the object-centre height."""

    projection: CameraProjection
    image_size: int
    object_height: float

    @classmethod
    def of_scene(cls, task: str, camera: str, image_size: int) -> SceneGeometry:
        """The geometry of a task's camera at ``image_size`` pixels (builds the scene once)."""
        return cls(camera_projection(task, camera), int(image_size), OBJECT_CENTRE_HEIGHT[task])

    def objects_to_pixels(self, object_pos: Tensor) -> Tensor:
        """[*B, N, 2] metres -> [*B, N, 2] pixels."""
        uv = self.projection.objects_to_image(object_pos, self.object_height)
        return normalised_to_pixels(uv, self.image_size)
