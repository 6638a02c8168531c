"""MJCF of the pushing scene: table, cameras, pusher and object bodies.

The pusher is a capsule on three slide joints driven by ``intvelocity`` actuators (a velocity
command integrated into a position target), so it collides with objects, unlike a mocap body.
It does not collide with the table (contact bit masks). Every object body has a free joint
named like the body; for blocks the cuboid sizes are placeholders overwritten each episode.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from kinet_rl.envs.textures import TABLE_TEXTURES
from kinet_rl.envs.workspace import Workspace
from kinet_rl.envs.ycb import YcbObject

__all__ = [
    "SceneLayout",
    "blocks_scene_xml",
    "ycb_scene_xml",
    "CAMERAS",
    "CameraFraming",
    "CAMERA_FRAMINGS",
    "PUSHER_RADIUS",
    "PUSHER_HALF_LENGTH",
]

CAMERAS = ("top", "side")
TIMESTEP = 0.005
PUSHER_RADIUS = 0.01
PUSHER_HALF_LENGTH = 0.04
PUSHER_PARK = (3.0, 3.0, 1.0)  # far outside both camera views
FRICTION = "0.5 0.005 0.0001"
#: YCB objects include cans and a bowl that roll: their contacts get torsional and rolling
#: friction (condim 6), so a pushed can or bowl stops instead of rolling off the table.
YCB_CONTACT = 'friction="0.5 0.01 0.002" condim="6"'
TOP_CAMERA_HEIGHT = 1.0


@dataclass(frozen=True)
class CameraFraming:
    """Where the top and side cameras of a task look (metres and degrees).

    The top camera looks straight down from ``TOP_CAMERA_HEIGHT`` and sees the square
    ``[-top_view, top_view]^2``. The side camera sits ``side_distance`` from the table centre at
    ``side_elevation`` above the table on the ``-y`` side; its axis points ``side_pitch`` below
    the horizontal (the elevation: it looks at the table centre) with a vertical field of view
    of ``side_fovy``.
    """

    top_view: float
    side_elevation: float
    side_distance: float
    side_pitch: float
    side_fovy: float

    def side_position(self, table_height: float) -> tuple[float, float, float]:
        """The side camera's position in the world frame."""
        e = math.radians(self.side_elevation)
        return (
            0.0,
            -self.side_distance * math.cos(e),
            table_height + self.side_distance * math.sin(e),
        )

    @classmethod
    def fitted(
        cls, view: float, object_height: float, elevation: float, distance: float
    ) -> CameraFraming:
        """The framing whose side camera just sees the square ``[-view, view]^2`` on the table.

        The pitch centres the near edge (on the table) and the far edge (``object_height``
        above it) vertically; the field of view is the smallest that holds both edges and
        the near corners (the widest part of the square in a perspective image).
        """
        e = math.radians(elevation)
        camera = np.array([0.0, -distance * math.cos(e), distance * math.sin(e)])

        def below_horizon(point: np.ndarray) -> float:
            ray = point - camera
            return math.atan2(-ray[2], ray[1])

        near = below_horizon(np.array([0.0, -view, 0.0]))
        far = below_horizon(np.array([0.0, view, object_height]))
        pitch = (near + far) / 2
        forward = np.array([0.0, math.cos(pitch), -math.sin(pitch)])
        corner = np.array([view, -view, 0.0]) - camera
        tan_half = max(math.tan((near - far) / 2), corner[0] / (corner @ forward))
        return cls(
            top_view=view,
            side_elevation=elevation,
            side_distance=distance,
            side_pitch=math.degrees(pitch),
            side_fovy=math.degrees(2 * math.atan(tan_half)),
        )


#: Camera framing of each task. BlockObjs keeps the framing its datasets and shipped weights
#: were made with (the side camera also sees the floor behind the table); YCBObjs cameras are
#: fitted to the reach of the pushes (1.25 x the workspace) on a table that fills both images.
CAMERA_FRAMINGS: dict[str, CameraFraming] = {
    "blocks": CameraFraming(
        top_view=0.25,
        side_elevation=40.0,
        side_distance=1.1,
        side_pitch=40.0,
        side_fovy=math.degrees(2 * math.atan(1.12 * 0.25 / 1.1)),
    ),
    "ycb": CameraFraming.fitted(view=0.375, object_height=0.1, elevation=50.0, distance=1.3),
}


@dataclass(frozen=True)
class SceneLayout:
    """Names of the bodies and geoms the task needs, in object order."""

    object_bodies: tuple[str, ...]
    table_materials: tuple[str, ...]


def _header(name: str, workspace: Workspace, image_size: int, midphase: bool) -> str:
    offscreen = max(image_size, 256)
    texture_assets = "\n".join(
        f'    <texture name="table_{t}" type="2d" file="{t}.png"/>\n'
        f'    <material name="table_{t}" texture="table_{t}" texrepeat="2 2" specular="0.1"/>'
        for t in TABLE_TEXTURES
    )
    return f"""<mujoco model="{name}">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{TIMESTEP}" integrator="implicitfast">
    <flag midphase="{"enable" if midphase else "disable"}" warmstart="enable"/>
  </option>
  <visual>
    <global offwidth="{offscreen}" offheight="{offscreen}"/>
    <headlight ambient="0.45 0.45 0.45" diffuse="0.45 0.45 0.45" specular="0 0 0"/>
  </visual>
  <asset>
{texture_assets}
    <material name="floor" rgba="0.22 0.22 0.25 1"/>
    <material name="pusher" rgba="0.15 0.15 0.15 1"/>
"""


def _world(workspace: Workspace, framing: CameraFraming, object_xml: str) -> str:
    th, half = workspace.table_height, workspace.table_half_size
    fovy = math.degrees(2 * math.atan(framing.top_view / TOP_CAMERA_HEIGHT))
    side_pos = framing.side_position(th)
    pitch = math.radians(framing.side_pitch)
    s, c = math.sin(pitch), math.cos(pitch)
    return f"""  <worldbody>
    <light name="key" pos="0.4 -0.4 1.5" dir="-0.25 0.25 -1" directional="true" castshadow="false" diffuse="0.45 0.45 0.45"/>
    <geom name="floor" type="plane" size="4 4 0.1" pos="0 0 {th - 0.75}" material="floor" contype="0" conaffinity="0"/>
    <geom name="table" type="box" pos="0 0 {th - 0.025}" size="{half} {half} 0.025" material="table_plain" friction="{FRICTION}"/>
    <camera name="top" pos="0 0 {th + TOP_CAMERA_HEIGHT}" xyaxes="1 0 0 0 1 0" fovy="{fovy:.4f}"/>
    <camera name="side" pos="{side_pos[0]} {side_pos[1]:.4f} {side_pos[2]:.4f}" xyaxes="1 0 0 0 {s:.5f} {c:.5f}" fovy="{framing.side_fovy:.4f}"/>
    <body name="pusher" gravcomp="1">
      <joint name="pusher_x" type="slide" axis="1 0 0"/>
      <joint name="pusher_y" type="slide" axis="0 1 0"/>
      <joint name="pusher_z" type="slide" axis="0 0 1"/>
      <geom name="pusher" type="capsule" size="{PUSHER_RADIUS} {PUSHER_HALF_LENGTH}" mass="0.5"
            material="pusher" contype="2" conaffinity="2" friction="{FRICTION}" solref="0.005 1"/>
    </body>
{object_xml}  </worldbody>
  <actuator>
    <intvelocity name="pusher_x" joint="pusher_x" kp="4000" dampratio="1" actrange="-5 5" forcerange="-60 60"/>
    <intvelocity name="pusher_y" joint="pusher_y" kp="4000" dampratio="1" actrange="-5 5" forcerange="-60 60"/>
    <intvelocity name="pusher_z" joint="pusher_z" kp="4000" dampratio="1" actrange="-5 5" forcerange="-20 20"/>
  </actuator>
</mujoco>
"""


def blocks_scene_xml(
    workspace: Workspace, num_objects: int, image_size: int
) -> tuple[str, SceneLayout]:
    """MJCF of the BlockObjs scene with ``num_objects`` two-cuboid bodies ``obj_<i>``."""
    bodies = []
    for i in range(num_objects):
        bodies.append(
            f"""    <body name="obj_{i}" pos="{1.0 + i} -3 0.5">
      <freejoint name="obj_{i}"/>
      <geom name="obj_{i}_a" type="box" size="0.05 0.02 0.015" density="600" conaffinity="3" friction="{FRICTION}"/>
      <geom name="obj_{i}_b" type="box" size="0.02 0.05 0.015" pos="0 0.05 0" density="600" conaffinity="3" friction="{FRICTION}"/>
    </body>
"""
        )
    xml = (
        _header("kinet_push_blocks", workspace, image_size, midphase=False)
        + "  </asset>\n"
        + _world(workspace, CAMERA_FRAMINGS["blocks"], "".join(bodies))
    )
    layout = SceneLayout(
        tuple(f"obj_{i}" for i in range(num_objects)), tuple(f"table_{t}" for t in TABLE_TEXTURES)
    )
    return xml, layout


def ycb_scene_xml(
    workspace: Workspace, objects: Sequence[YcbObject], image_size: int
) -> tuple[str, SceneLayout]:
    """MJCF of the YCBObjs scene with one body ``ycb_<name>`` per candidate object."""
    assets, bodies = [], []
    for i, obj in enumerate(objects):
        n = f"ycb_{obj.name}"
        assets.append(
            f'    <texture name="{n}_tex" type="2d" file="{obj.texture}"/>\n'
            f'    <material name="{n}_mat" texture="{n}_tex" specular="0.2" shininess="0.2"/>\n'
            f'    <mesh name="{n}_visual" file="{obj.visual_mesh}"/>\n'
            + "".join(
                f'    <mesh name="{n}_col{k}" file="{path}"/>\n'
                for k, path in enumerate(obj.collision_meshes)
            )
        )
        collision = "".join(
            f'      <geom name="{n}_col{k}" type="mesh" mesh="{n}_col{k}" group="3" density="{obj.density}" '
            f'conaffinity="3" {YCB_CONTACT} rgba="0.5 0.5 0.5 0.3"/>\n'
            for k in range(len(obj.collision_meshes))
        )
        bodies.append(
            f"""    <body name="{n}" pos="{1.0 + 0.5 * i} -3 0.5">
      <freejoint name="{n}"/>
      <geom name="{n}_visual" type="mesh" mesh="{n}_visual" material="{n}_mat" contype="0" conaffinity="0" group="2" mass="0"/>
{collision}    </body>
"""
        )
    xml = (
        _header("kinet_push_ycb", workspace, image_size, midphase=True)
        + "".join(assets)
        + "  </asset>\n"
        + _world(workspace, CAMERA_FRAMINGS["ycb"], "".join(bodies))
    )
    layout = SceneLayout(
        tuple(f"ycb_{o.name}" for o in objects), tuple(f"table_{t}" for t in TABLE_TEXTURES)
    )
    return xml, layout
