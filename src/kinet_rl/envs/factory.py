"""Factories: the raw dm_control environment and the TorchRL environment."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

from dm_control.rl import control

from kinet_rl.config_schema import check_arguments, require
from kinet_rl.envs.scene import blocks_scene_xml, ycb_scene_xml
from kinet_rl.envs.settings import MAX_OBJECTS, SceneSettings
from kinet_rl.envs.task import PushObjects, PushPhysics, PushSettings
from kinet_rl.envs.textures import table_texture_assets
from kinet_rl.envs.workspace import workspace_for
from kinet_rl.envs.ycb import load_ycb_objects

#: Push settings of each task. A YCB push that would start on top of an object (they are up
#: to 21 cm across) lifts the pusher again instead of dragging the object along; BlockObjs keeps
#: the behaviour its datasets were collected with.
DEFAULT_PUSH_SETTINGS = {"blocks": PushSettings(), "ycb": PushSettings(retract_when_blocked=True)}

__all__ = [
    "DEFAULT_PUSH_SETTINGS",
    "PushEnvironment",
    "check_env_arguments",
    "make_dm_env",
    "make_env",
    "MAX_OBJECTS",
]


class PushEnvironment(control.Environment):
    """``control.Environment`` whose reward spec is the task's (float32, not float64)."""

    def reward_spec(self):
        """The task's reward spec."""
        return self.task.reward_spec()

    def close(self) -> None:
        """Release rendering resources."""
        self.task.close()


def make_dm_env(
    task: str = "blocks",
    num_objects: int = 3,
    camera: str = "top",
    image_size: int = 64,
    geometry: str = "train",
    background: str = "fixed",
    seed: int | None = None,
    ycb_dir: str | os.PathLike | None = None,
    ycb_objects: Sequence[str] | None = None,
    settings: PushSettings | None = None,
) -> PushEnvironment:
    """Build the raw dm_control pushing environment (no time limit).

    Args:
        task: ``"blocks"`` (BlockObjs) or ``"ycb"`` (YCBObjs).
        num_objects: objects per episode, 1 to 5.
        camera: ``"top"`` (overhead) or ``"side"`` (angled).
        image_size: height and width of the ``pixels`` observation.
        geometry: block sizes, ``"train"`` or elongated out-of-distribution ``"gen"``;
            ignored for YCB (hold objects out with ``ycb_objects`` instead).
        background: ``"fixed"`` table or ``"random"`` texture and tint per episode.
        seed: seed of the task's random state.
        ycb_dir: YCB asset folder with ``manifest.json``; defaults to ``$KINET_RL_YCB_DIR``.
        ycb_objects: names of the YCB objects to draw from (default: all in the manifest).
        settings: push speeds and thresholds (default: ``DEFAULT_PUSH_SETTINGS[task]``).
    """
    objects = None if ycb_objects is None else tuple(ycb_objects)
    SceneSettings(task, num_objects, camera, image_size, geometry, background, objects)  # checks
    workspace = workspace_for(task)
    candidates = None
    if task == "blocks":
        xml, layout = blocks_scene_xml(workspace, num_objects, image_size)
    else:
        candidates = load_ycb_objects(ycb_dir, ycb_objects)
        if len(candidates) < num_objects:
            raise ValueError(
                f"num_objects={num_objects} exceeds the {len(candidates)} YCB objects to draw from; "
                "list more names in ycb_objects or use fewer objects."
            )
        xml, layout = ycb_scene_xml(workspace, candidates, image_size)
    physics = PushPhysics.from_xml_string(xml, assets=table_texture_assets())
    push_task = PushObjects(
        layout,
        workspace,
        num_objects=num_objects,
        camera=camera,
        image_size=image_size,
        background=background,
        geometry=geometry,
        ycb_objects=candidates,
        settings=settings or DEFAULT_PUSH_SETTINGS[task],
        random=seed,
    )
    return PushEnvironment(physics, push_task, time_limit=float("inf"), legacy_step=False)


def make_env(
    task: str = "blocks",
    num_objects: int = 3,
    camera: str = "top",
    image_size: int = 64,
    geometry: str = "train",
    background: str = "fixed",
    seed: int | None = None,
    max_steps: int | None = 60,
    ycb_dir: str | os.PathLike | None = None,
    ycb_objects: Sequence[str] | None = None,
    device: str = "cpu",
):
    """Build the TorchRL pushing environment (a ``DMControlWrapper``).

    Keys: ``pixels`` uint8 ``[H, W, 3]``, ``object_pos`` float32 ``[N, 2]``, ``object_yaw``
    float32 ``[N]``, ``object_shape`` float32 ``[N, 8]``, ``unstable`` bool ``[1]``; ``action``
    float32 ``[4]`` in [-1, 1].
    With ``max_steps`` a ``StepCounter`` truncates episodes after that many pushes.

    Args: as :func:`make_dm_env`, plus ``max_steps`` (``None``: no step limit) and ``device``.
    """
    from torchrl.envs import DMControlWrapper, StepCounter, TransformedEnv

    dm_env = make_dm_env(
        task=task,
        num_objects=num_objects,
        camera=camera,
        image_size=image_size,
        geometry=geometry,
        background=background,
        seed=seed,
        ycb_dir=ycb_dir,
        ycb_objects=ycb_objects,
    )
    env = DMControlWrapper(dm_env, device=device)
    if seed is not None:
        env.set_seed(seed)
    if max_steps is not None:
        env = TransformedEnv(env, StepCounter(max_steps=max_steps))
    return env


def check_env_arguments(values: Mapping[str, Any]) -> SceneSettings:
    """Checks :func:`make_env` keyword arguments (an ``env`` config group) without building.

    Returns:
        The scene they define.

    Raises:
        ConfigError: An unknown key, a wrong type or an out-of-range value, named.
    """
    args = check_arguments(make_env, values)
    max_steps = args["max_steps"]
    require(max_steps is None or max_steps >= 1, "max_steps", max_steps, "null or at least 1")
    return SceneSettings.from_mapping(args)
