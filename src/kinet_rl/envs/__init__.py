"""Pushing environments (dm_control Physics + Task), ``make_env`` and gymnasium ids.

Importing this package registers the gymnasium ids ``kinet_rl/PushBlocks-v0`` and
``kinet_rl/PushYCB-v0``.
"""

from __future__ import annotations

from kinet_rl.envs.factory import PushEnvironment, make_dm_env, make_env
from kinet_rl.envs.geometry import CameraProjection, SceneGeometry
from kinet_rl.envs.gym_env import GYM_IDS, PushGymEnv, register_gym_envs
from kinet_rl.envs.settings import SceneSettings
from kinet_rl.envs.task import PushObjects, PushPhysics, PushSettings
from kinet_rl.envs.workspace import Workspace, workspace_for

register_gym_envs()

__all__ = [
    "GYM_IDS",
    "CameraProjection",
    "PushEnvironment",
    "PushGymEnv",
    "PushObjects",
    "PushPhysics",
    "PushSettings",
    "SceneGeometry",
    "SceneSettings",
    "Workspace",
    "make_dm_env",
    "make_env",
    "workspace_for",
]
