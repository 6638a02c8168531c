"""The pushing task: a dm_control ``Physics`` and the ``PushObjects`` task.

One environment step executes one straight-line push. The action is 4-d in [-1, 1]: push start
(x, y) and end (x, y) normalised to the workspace. The pusher appears above the start (it is
placed there directly, being high above all objects), lowers, pushes to the end, lifts, and is
parked out of view; then the scene settles until every object is at rest (with a cap).
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import weakref
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
from dm_control import mujoco as dm_mujoco
from dm_control.suite import base
from dm_env import specs

from kinet_rl.envs import blocks
from kinet_rl.envs.placement import sample_placements
from kinet_rl.envs.scene import PUSHER_HALF_LENGTH, PUSHER_PARK, PUSHER_RADIUS, SceneLayout
from kinet_rl.envs.workspace import Workspace
from kinet_rl.envs.ycb import YcbObject
from kinet_rl.keys import OBJECT_POS, OBJECT_SHAPE, OBJECT_YAW, PIXELS, UNSTABLE

__all__ = ["PushPhysics", "PushObjects", "PushSettings"]

logger = logging.getLogger(__name__)

# Renderers must be closed before EGL is terminated at exit (mujoco registers that atexit hook
# when the first GL context is made, so the hook below, registered later, runs before it).
_TASKS_WITH_RENDERER: weakref.WeakSet = weakref.WeakSet()
_exit_hook_registered = False


def _close_renderers() -> None:
    for task in list(_TASKS_WITH_RENDERER):
        task.close()


def _close_at_exit(task: PushObjects) -> None:
    global _exit_hook_registered
    _TASKS_WITH_RENDERER.add(task)
    if not _exit_hook_registered:
        atexit.register(_close_renderers)
        _exit_hook_registered = True


_BAD_STATE_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
)
#: A lowered pusher that, after ``BLOCKED_HOLD_STEPS`` of holding still (its servo lags ~1 cm
#: while moving), is farther than this (metres) from its target was stopped by an object.
BLOCKED_TOLERANCE = 0.005
BLOCKED_HOLD_STEPS = 20
#: Draws of the objects (geometry or YCB subset) an episode may take when no collision-free
#: placement fits the drawn ones, e.g. 5 elongated ``gen`` blocks on the blocks table.
OBJECT_DRAWS = 10


@dataclass(frozen=True)
class PushSettings:
    """Speeds and thresholds of a push (SI units).

    Attributes:
        push_speed: pusher speed along the push, m/s.
        vertical_speed: pusher speed when lowering and lifting, m/s.
        tip_clearance: gap between pusher tip and table while pushing, m.
        settle_chunk: physics steps between rest checks while settling.
        settle_max_steps: cap on settling steps after a push.
        rest_speed: objects are at rest below this linear speed (m/s) ...
        rest_angular_speed: ... and this angular speed (rad/s).
        blowup_speed: an object faster than this (m/s) means a blown-up contact.
        blowup_angular_speed: same for angular speed (rad/s).
        retract_when_blocked: when an object stops the lowering pusher (the push starts on top
            of it), lift the pusher again instead of dragging the object along the push.
    """

    push_speed: float = 0.25
    vertical_speed: float = 0.5
    tip_clearance: float = 0.004
    settle_chunk: int = 10
    settle_max_steps: int = 300
    rest_speed: float = 0.005
    rest_angular_speed: float = 0.05
    blowup_speed: float = 3.0
    blowup_angular_speed: float = 60.0
    retract_when_blocked: bool = False


class PushPhysics(dm_mujoco.Physics):
    """Physics of the pushing scene.

    MuJoCo's bad-state warnings do not raise ``PhysicsError`` here: :class:`PushObjects` detects
    them, flags the episode ``unstable``, counts and logs it.
    """

    @contextlib.contextmanager
    def check_invalid_state(self) -> Iterator[None]:
        """No-op: invalid states are handled by the task (see the class docstring)."""
        yield

    def planar_poses(self, qpos_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Planar positions ``[N, 2]`` and yaws ``[N]`` (float32) of free joints at ``qpos_ids`` ``[N, 7]``."""
        poses = self.data.ptr.qpos[qpos_ids].reshape(-1, 7)
        w, x, y, z = poses[:, 3], poses[:, 4], poses[:, 5], poses[:, 6]
        yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        return poses[:, :2].astype(np.float32), yaw.astype(np.float32)


class PushObjects(base.Task):
    """Push 1 to 5 objects on a table with a capsule pusher, one push per step.

    Observations: ``pixels`` uint8 ``[H, W, 3]`` from the chosen camera; for evaluation only,
    ``object_pos`` float32 ``[N, 2]`` (metres, table frame), ``object_yaw`` float32 ``[N]``,
    ``object_shape`` float32 ``[N, 8]`` (the episode's body-frame footprints as two boxes, see
    :data:`~kinet_rl.keys.OBJECT_SHAPE`: a block's two cuboids, a YCB object's bounding box twice)
    and ``unstable`` bool ``[1]``. An unstable simulation (NaN state, MuJoCo's bad-acceleration
    reset, a blown-up contact, an object off the table) ends the episode with ``unstable``
    set, increments :attr:`unstable_count` and logs a warning.

    Args:
        layout: names of the object bodies and table materials in the MJCF.
        workspace: workspace geometry of the task.
        num_objects: objects in each episode.
        camera: ``"top"`` or ``"side"``.
        image_size: height and width of ``pixels``.
        background: ``"fixed"`` (one table texture) or ``"random"`` (texture and tint per episode).
        geometry: block size range, ``"train"`` or ``"gen"`` (blocks only).
        ycb_objects: the candidate YCB objects (same order as ``layout.object_bodies``), or
            ``None`` for blocks.
        settings: push speeds and thresholds.
        random: seed or ``np.random.RandomState``; all randomness is drawn from it.
    """

    def __init__(
        self,
        layout: SceneLayout,
        workspace: Workspace,
        num_objects: int,
        camera: str,
        image_size: int,
        background: str,
        geometry: str = "train",
        ycb_objects: Sequence[YcbObject] | None = None,
        settings: PushSettings | None = None,
        random: int | np.random.RandomState | None = None,
    ) -> None:
        super().__init__(random=random)
        self.layout = layout
        self.workspace = workspace
        self.num_objects = num_objects
        self.camera = camera
        self.image_size = image_size
        self.background = background
        self.geometry = geometry
        self.ycb_objects = list(ycb_objects) if ycb_objects is not None else None
        self.settings = settings or PushSettings()
        self.fixed_texture = "table_wood" if self.ycb_objects is not None else "table_plain"
        self.unstable_count = 0
        self._unstable = False
        self._renderer: mujoco.Renderer | None = None
        self._qpos_ids = np.zeros((num_objects, 7), dtype=int)  # free-joint addresses of the
        self._dof_ids = np.zeros((num_objects, 6), dtype=int)  # episode's objects
        no_ids = np.zeros(3, dtype=int)
        self._pusher = (no_ids, no_ids, no_ids)  # pusher qpos, dof and activation addresses
        self.active: tuple[str, ...] = layout.object_bodies[:num_objects]
        self._footprint = np.zeros((num_objects, 2))  # body-frame footprint half extents
        self._footprint_offset = np.zeros((num_objects, 2))  # and centre
        self._shape = np.zeros((num_objects, 8), dtype=np.float32)  # OBJECT_SHAPE
        self._rest_height = np.zeros(num_objects)
        self._object_height = np.zeros(num_objects)

    # ----------------------------------------------------------------- episode set-up
    def initialize_episode(self, physics: PushPhysics) -> None:
        """Draw objects, colours, background and a collision-free placement (drawing the objects
        again when no placement fits them); let it settle."""
        self._unstable = False
        model = physics.model
        for draw in range(OBJECT_DRAWS):
            if self.ycb_objects is None:
                self._draw_blocks(physics)
            else:
                self._draw_ycb(physics, self.ycb_objects)
            self._draw_background(physics)
            self._index_objects(physics)
            try:
                xy, yaw = sample_placements(
                    self.random,
                    self._footprint,
                    self.workspace.half_size,
                    offsets=self._footprint_offset,
                )
                break
            except ValueError:
                if draw == OBJECT_DRAWS - 1:
                    raise
        physics.data.qvel[:] = 0.0
        self._park_pusher(physics)
        self.set_object_poses(physics, xy, yaw)
        mujoco.mj_forward(model.ptr, physics.data.ptr)
        self._settle(physics)

    def _index_objects(self, physics: PushPhysics) -> None:
        """Cache the qpos / qvel addresses of the episode's objects and the pusher."""
        model = physics.model
        joints = [model.name2id(body, "joint") for body in self.active]
        self._qpos_ids = model.jnt_qposadr[joints][:, None] + np.arange(7)
        self._dof_ids = model.jnt_dofadr[joints][:, None] + np.arange(6)
        pusher_joints = [model.name2id(f"pusher_{a}", "joint") for a in "xyz"]
        actuators = [model.name2id(f"pusher_{a}", "actuator") for a in "xyz"]
        self._pusher = (
            model.jnt_qposadr[pusher_joints],
            model.jnt_dofadr[pusher_joints],
            model.actuator_actadr[actuators],
        )

    def _draw_blocks(self, physics: PushPhysics) -> None:
        model = physics.model
        colors = blocks.sample_colors(self.random, self.num_objects)
        for i, body in enumerate(self.active):
            block = blocks.sample_block_geometry(self.random, self.geometry)
            geom_ids = (model.name2id(f"{body}_a", "geom"), model.name2id(f"{body}_b", "geom"))
            blocks.apply_block_geometry(model.ptr, model.name2id(body, "body"), geom_ids, block)
            model.geom_rgba[list(geom_ids)] = colors[i]
            self._footprint_offset[i], self._footprint[i] = block.footprint
            self._shape[i] = block.planar_boxes.reshape(8)
            self._rest_height[i] = block.sizes[0, 2]
            self._object_height[i] = 2.0 * block.sizes[0, 2]
        mujoco.mj_setConst(model.ptr, physics.data.ptr)

    def _draw_ycb(self, physics: PushPhysics, candidates: list[YcbObject]) -> None:
        model = physics.model
        chosen = self.random.choice(len(candidates), self.num_objects, replace=False)
        self.active = tuple(self.layout.object_bodies[i] for i in chosen)
        for index, body in enumerate(self.layout.object_bodies):
            in_use = index in chosen
            body_id = model.name2id(body, "body")
            model.body_gravcomp[body_id] = 0.0 if in_use else 1.0
            geoms = np.flatnonzero(model.geom_bodyid == body_id)
            collision = geoms[model.geom_group[geoms] == 3]
            model.geom_contype[collision] = 1 if in_use else 0
            model.geom_conaffinity[collision] = 3 if in_use else 0
            if not in_use:  # park far away, at rest, without contacts
                physics.named.data.qpos[body] = [-3.0 - index, 3.0, 1.0, 1.0, 0.0, 0.0, 0.0]
        objects = [candidates[i] for i in chosen]
        self._footprint = np.stack([o.half_extents[:2] for o in objects])
        box = np.concatenate([self._footprint_offset, self._footprint], axis=1)  # [N, 4]
        self._shape = np.tile(box, 2).astype(np.float32)  # the footprint box twice
        self._rest_height = np.array([o.rest_height for o in objects])
        self._object_height = 2.0 * self._rest_height

    def _draw_background(self, physics: PushPhysics) -> None:
        model = physics.model
        table = model.name2id("table", "geom")
        if self.background == "fixed":
            material = self.fixed_texture
            tint = np.ones(4)
        else:
            material = self.layout.table_materials[
                self.random.randint(len(self.layout.table_materials))
            ]
            tint = np.append(self.random.uniform(0.45, 1.0, size=3), 1.0)
        mat_id = model.name2id(material, "material")
        model.geom_matid[table] = mat_id
        model.mat_rgba[mat_id] = tint

    # ----------------------------------------------------------------- object poses
    def set_object_poses(self, physics: PushPhysics, xy: np.ndarray, yaw: np.ndarray) -> None:
        """Place the episode's objects at table-frame ``xy`` ``[N, 2]`` (metres) and ``yaw`` ``[N]``, at rest.

        Useful to render a goal configuration; call ``physics.forward()`` (done here) before
        rendering. Objects rest on the table in their stable pose.
        """
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        yaw = np.asarray(yaw, dtype=float).reshape(-1)
        if len(xy) != len(self.active) or len(yaw) != len(self.active):
            raise ValueError(
                f"set_object_poses needs {len(self.active)} poses (one per object), got xy {xy.shape} and yaw {yaw.shape}."
            )
        for i, body in enumerate(self.active):
            z = self.workspace.table_height + self._rest_height[i]
            quat = [np.cos(yaw[i] / 2), 0.0, 0.0, np.sin(yaw[i] / 2)]
            physics.named.data.qpos[body] = [xy[i, 0], xy[i, 1], z, *quat]
            physics.named.data.qvel[body] = 0.0
        physics.forward()

    def object_poses(self, physics: PushPhysics) -> tuple[np.ndarray, np.ndarray]:
        """Planar positions ``[N, 2]`` (metres, table frame) and yaws ``[N]`` of the episode's objects."""
        return physics.planar_poses(self._qpos_ids)

    # ----------------------------------------------------------------- the push
    def action_spec(self, physics: PushPhysics) -> specs.BoundedArray:
        """Push start (x, y) and end (x, y), normalised to the workspace."""
        return specs.BoundedArray((4,), np.float32, -1.0, 1.0, name="action")

    def reward_spec(self) -> specs.Array:
        """A constant zero reward (planners define their own costs), float32."""
        return specs.Array((), np.float32, name="reward")

    def push_plan(self, action: np.ndarray) -> tuple[np.ndarray, list[tuple[np.ndarray, float]]]:
        """The pusher's start ``[3]`` (above the push start) and its ``(target [3], speed)`` moves.

        The moves lower the pusher to pushing height, push to the end point and lift it clear
        of the tallest object of the episode.
        """
        start, end = self.workspace.push_endpoints(action)
        s = self.settings
        push_z = self.workspace.table_height + s.tip_clearance + PUSHER_RADIUS + PUSHER_HALF_LENGTH
        clear_z = push_z + float(self._object_height.max()) + 0.01
        moves = [
            (np.array([start[0], start[1], push_z]), s.vertical_speed),
            (np.array([end[0], end[1], push_z]), s.push_speed),
            (np.array([end[0], end[1], clear_z]), s.vertical_speed),
        ]
        return np.array([start[0], start[1], clear_z]), moves

    def before_step(self, action: np.ndarray, physics: PushPhysics) -> None:
        """Execute one push: appear above the start, lower, push to the end, lift, park."""
        above_start, (lower, push, lift) = self.push_plan(action)
        self._place_pusher(physics, above_start)
        self._move_pusher(physics, *lower)
        if self.settings.retract_when_blocked and self._hold_pusher_and_check_blocked(
            physics, lower[0]
        ):
            self._move_pusher(physics, above_start, lift[1])
        else:
            self._move_pusher(physics, *push)
            self._move_pusher(physics, *lift)
        self._park_pusher(physics)
        self._check_unstable(physics)

    def after_step(self, physics: PushPhysics) -> None:
        """Let the scene settle, then check stability."""
        if not self._unstable:
            self._settle(physics)

    # Hot paths below use the raw ``mujoco.MjData`` / ``MjModel`` (``.ptr``): dm_control's
    # named wrappers cost more than the physics of a short push.
    def _place_pusher(self, physics: PushPhysics, xyz: Sequence[float] | np.ndarray) -> None:
        data = physics.data.ptr
        qpos_ids, dof_ids, act_ids = self._pusher
        data.qpos[qpos_ids] = xyz
        data.qvel[dof_ids] = 0.0
        data.act[act_ids] = xyz
        data.ctrl[:] = 0.0

    def _hold_pusher_and_check_blocked(self, physics: PushPhysics, target: np.ndarray) -> bool:
        """Holds the pusher still, then whether an object stopped it short of ``target``."""
        mujoco.mj_step(physics.model.ptr, physics.data.ptr, nstep=BLOCKED_HOLD_STEPS)
        position = physics.data.ptr.qpos[self._pusher[0]]
        return bool(np.linalg.norm(position - target) > BLOCKED_TOLERANCE)

    def _park_pusher(self, physics: PushPhysics) -> None:
        self._place_pusher(physics, PUSHER_PARK)

    def _move_pusher(self, physics: PushPhysics, target: np.ndarray, speed: float) -> None:
        """Move the pusher's position target in a straight line at ``speed``; one ``mj_step`` call."""
        model, data = physics.model.ptr, physics.data.ptr
        delta = target - data.act[self._pusher[2]]
        dt = model.opt.timestep
        steps = max(1, int(np.ceil(np.sqrt(delta @ delta) / (speed * dt))))
        data.ctrl[:] = delta / (steps * dt)
        mujoco.mj_step(model, data, nstep=steps)
        data.ctrl[:] = 0.0

    def _settle(self, physics: PushPhysics) -> None:
        """Step in chunks until all objects rest (or the cap), checking stability."""
        s = self.settings
        model, data = physics.model.ptr, physics.data.ptr
        for _ in range(0, s.settle_max_steps, s.settle_chunk):
            mujoco.mj_step(model, data, nstep=s.settle_chunk)
            if self._check_unstable(physics):
                return
            lin, ang = self._object_speeds(data)
            if lin.max(initial=0.0) < s.rest_speed and ang.max(initial=0.0) < s.rest_angular_speed:
                return

    def _object_speeds(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        qvel_sq = np.square(data.qvel[self._dof_ids])
        return np.sqrt(qvel_sq[:, :3].sum(axis=1)), np.sqrt(qvel_sq[:, 3:].sum(axis=1))

    # ----------------------------------------------------------------- stability
    def _check_unstable(self, physics: PushPhysics) -> bool:
        """Detect and record an unstable simulation; returns whether it is unstable."""
        if self._unstable:
            return True
        data = physics.data.ptr
        reason = self._instability_reason(data)
        if reason is None:
            return False
        self._unstable = True
        self.unstable_count += 1
        logger.warning(
            "Unstable simulation (%s); ending the episode (%d so far).", reason, self.unstable_count
        )
        if not (np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all()):
            data.qpos[:] = physics.model.ptr.qpos0  # keep the state valid for rendering
            data.qvel[:] = 0.0
            data.act[:] = 0.0
        for warning in _BAD_STATE_WARNINGS:
            data.warning[warning].number = 0
        return True

    def _instability_reason(self, data: mujoco.MjData) -> str | None:
        s = self.settings
        if not (np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all()):
            return "NaN or infinite state"
        bad = [w.name for w in _BAD_STATE_WARNINGS if data.warning[w].number > 0]
        if bad:
            return f"MuJoCo reset the simulation ({', '.join(bad)})"
        lin, ang = self._object_speeds(data)
        if lin.max() > s.blowup_speed or ang.max() > s.blowup_angular_speed:
            return f"velocity explosion (max speed {lin.max():.2f} m/s, {ang.max():.1f} rad/s)"
        positions = data.qpos[self._qpos_ids[:, :3]]
        off = (np.abs(positions[:, :2]) > self.workspace.table_half_size).any(axis=1)
        off |= positions[:, 2] < self.workspace.table_height - 0.02
        if off.any():
            return f"object {self.active[int(np.argmax(off))]} left the table"
        return None

    @property
    def unstable(self) -> bool:
        """Whether the current episode went unstable."""
        return self._unstable

    # ----------------------------------------------------------------- observations
    def get_observation(self, physics: PushPhysics) -> dict[str, np.ndarray]:
        """Pixels from the task's camera plus ground-truth poses, shapes and the ``unstable`` flag."""
        xy, yaw = self.object_poses(physics)
        return {
            PIXELS: self.render(physics),
            OBJECT_POS: xy,
            OBJECT_YAW: yaw,
            OBJECT_SHAPE: self._shape.copy(),
            UNSTABLE: np.array([self._unstable]),
        }

    def render(self, physics: PushPhysics) -> np.ndarray:
        """Render the task's camera: uint8 ``[H, W, 3]`` (one cached ``mujoco.Renderer``)."""
        if self._renderer is None or self._renderer.model is not physics.model.ptr:
            self.close()
            self._renderer = mujoco.Renderer(physics.model.ptr, self.image_size, self.image_size)
            _close_at_exit(self)
        self._renderer.update_scene(physics.data.ptr, camera=self.camera)
        return self._renderer.render()

    def close(self) -> None:
        """Release the renderer's GL context."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def get_reward(self, physics: PushPhysics) -> np.float32:
        """Zero: the task defines no reward; goal costs live in the planners."""
        return np.float32(0.0)

    def get_termination(self, physics: PushPhysics) -> float | None:
        """Discount 0 (episode ends) when the simulation went unstable, else ``None``."""
        return 0.0 if self._unstable else None
