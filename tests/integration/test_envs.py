"""Integration tests of the pushing environments (MuJoCo stepping and rendering)."""

from __future__ import annotations

import collections
import functools
import itertools
import json
import logging

import gymnasium
import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

from kinet_rl.envs import GYM_IDS, make_dm_env, make_env, workspace_for
from kinet_rl.envs.geometry import camera_projection
from kinet_rl.envs.scene import CAMERA_FRAMINGS

pytestmark = pytest.mark.slow

#: Skipped without the YCB assets ($KINET_RL_YCB_DIR; the ``ycb`` marker of tests/conftest.py).
needs_ycb = pytest.mark.ycb


def _maybe_ycb(task):
    return [needs_ycb] if task == "ycb" else []


# Pairwise cover of task x camera x objects x geometry x background.
VARIANTS = [
    ("blocks", "top", 1, "train", "fixed"),
    ("blocks", "side", 3, "gen", "random"),
    ("blocks", "top", 5, "gen", "random"),
    ("blocks", "side", 5, "train", "fixed"),
    ("ycb", "side", 1, "train", "random"),
    ("ycb", "top", 3, "train", "fixed"),
    ("ycb", "top", 5, "gen", "random"),
    ("ycb", "side", 5, "gen", "fixed"),
]


@pytest.mark.parametrize(
    "variant", [pytest.param(v, marks=_maybe_ycb(v[0]), id="-".join(map(str, v))) for v in VARIANTS]
)
def test_every_variant_steps_and_passes_check_env_specs(variant):
    task, camera, num, geometry, background = variant
    env = make_env(
        task=task,
        camera=camera,
        num_objects=num,
        geometry=geometry,
        background=background,
        seed=3,
        max_steps=2,
    )
    check_env_specs(env)
    td = env.rollout(5, break_when_any_done=True)
    assert td.shape == (2,)  # StepCounter truncates at max_steps
    assert td["next", "truncated"][-1].item()
    assert (
        td["next", "pixels"].shape == (2, 64, 64, 3) and td["next", "pixels"].dtype == torch.uint8
    )
    pos = td["next", "object_pos"]
    assert pos.shape == (2, num, 2) and pos.dtype == torch.float32
    assert td["next", "object_yaw"].shape == (2, num)
    assert td["next", "object_shape"].shape == (2, num, 8)
    assert torch.equal(td["next", "object_shape"][0], td["object_shape"][0])  # fixed per episode
    assert not td["next", "unstable"].any()
    assert (pos.abs() <= workspace_for(task).table_half_size).all()
    assert td["next", "pixels"].float().std() > 5.0  # a real image, not a blank frame


def test_same_seed_gives_identical_observations_and_other_seed_differs():
    action = torch.tensor([-0.6, -0.1, 0.7, 0.2])

    def rollout(seed):
        env = make_env(seed=seed, background="random")
        return env.rollout(3, policy=lambda td: td.set("action", action))

    first, second, other = rollout(7), rollout(7), rollout(8)
    assert torch.equal(first["next", "pixels"], second["next", "pixels"])
    assert torch.equal(first["next", "object_pos"], second["next", "object_pos"])
    assert not torch.equal(first["pixels"][0], other["pixels"][0])


def test_push_through_an_object_moves_it_and_a_far_push_moves_none():
    env = make_dm_env(num_objects=3, seed=11)
    ws = env.task.workspace
    pos0 = env.reset().observation["object_pos"]
    far = np.array([-1.0, -1.0, -1.0, -1.0])  # a zero-length push in a corner
    pos1 = env.step(far).observation["object_pos"]
    np.testing.assert_allclose(pos1, pos0, atol=1e-4)
    target = pos0[0]
    direction = -np.sign(target[0]) or 1.0  # push towards the centre
    start = target - direction * np.array([0.09, 0.0])
    end = target + direction * np.array([0.05, 0.0])
    pos2 = env.step(np.concatenate([ws.to_action(start), ws.to_action(end)])).observation[
        "object_pos"
    ]
    moved = np.linalg.norm(pos2 - pos1, axis=1)
    assert moved[0] > 0.03, f"the pushed object moved only {moved[0]:.4f} m"
    assert (pos2[0, 0] - pos1[0, 0]) * direction > 0.03  # along the push direction


def test_five_elongated_blocks_always_find_a_placement():
    """Five ``gen`` blocks do not always fit the table: the episode draws them again (before
    this, 5 of the 20 Table II test seeds 50000-50019 raised within 20 resets, e.g. 50000)."""
    for seed in (50000, 50006, 50008):
        env = make_dm_env(num_objects=5, geometry="gen", image_size=16, seed=seed)
        try:
            for _ in range(20):
                pos = env.reset().observation["object_pos"]
                assert np.abs(pos).max() < workspace_for("blocks").half_size
        finally:
            env.close()


def test_set_object_poses_round_trips():
    env = make_dm_env(num_objects=2, seed=0)
    env.reset()
    xy = np.array([[0.1, -0.05], [-0.1, 0.08]])
    yaw = np.array([0.3, -2.0])
    env.task.set_object_poses(env.physics, xy, yaw)
    got_xy, got_yaw = env.task.object_poses(env.physics)
    np.testing.assert_allclose(got_xy, xy, atol=1e-6)
    np.testing.assert_allclose(got_yaw, yaw, atol=1e-6)
    with pytest.raises(ValueError, match="needs 2 poses"):
        env.task.set_object_poses(env.physics, xy[:1], yaw[:1])


@needs_ycb
def test_ycb_objects_rest_stably_and_held_out_sets_work():
    names = ["003_cracker_box", "005_tomato_soup_can", "025_mug", "035_power_drill", "011_banana"]
    env = make_dm_env(task="ycb", num_objects=5, seed=2, ycb_objects=names)
    ts = env.reset()
    assert set(env.task.active) == {f"ycb_{n}" for n in names}
    pos0, yaw0 = ts.observation["object_pos"], ts.observation["object_yaw"]
    for _ in range(3):
        ts = env.step(np.array([1.0, 1.0, 1.0, 1.0]))  # far, zero-length pushes
    drift = np.abs(ts.observation["object_pos"] - pos0).max()
    turn = np.abs(np.angle(np.exp(1j * (ts.observation["object_yaw"] - yaw0)))).max()
    assert drift < 2e-3 and turn < 0.02, (drift, turn)
    with pytest.raises(ValueError, match="exceeds the 2 YCB objects"):
        make_dm_env(task="ycb", num_objects=3, ycb_objects=names[:2])


def test_unstable_flag_fires_on_blow_up_and_is_counted(caplog):
    env = make_env(num_objects=2, seed=0, max_steps=None)
    dm = env._env  # the wrapped dm_control environment
    far = torch.tensor([1.0, 1.0, 1.0, 1.0])
    td = env.step(env.reset().set("action", far))
    assert not td["next", "unstable"].item() and not td["next", "done"].item()
    # A blown-up contact: one object suddenly at 80 m/s.
    td = env.reset()
    dm.physics.named.data.qvel[dm.task.active[0]][:3] = [80.0, 0.0, 0.0]
    with caplog.at_level(logging.WARNING, logger="kinet_rl.envs.task"):
        td = env.step(td.set("action", far))
    assert td["next", "unstable"].item() and td["next", "terminated"].item()
    assert dm.task.unstable_count == 1
    assert "Unstable simulation (velocity explosion" in caplog.text
    # A NaN state: flagged, counted, and the physics state is made valid again.
    td = env.reset()
    assert not td["unstable"].item()
    dm.physics.data.qpos[-1] = np.nan
    with caplog.at_level(logging.WARNING, logger="kinet_rl.envs.task"):
        td = env.step(td.set("action", far))
    assert td["next", "unstable"].item() and td["next", "terminated"].item()
    assert dm.task.unstable_count == 2
    assert "MuJoCo reset the simulation (mjWARN_BADQPOS)" in caplog.text
    assert np.all(np.isfinite(dm.physics.data.qpos))


@pytest.mark.parametrize("task", [pytest.param(t, marks=_maybe_ycb(t)) for t in GYM_IDS])
def test_gymnasium_ids(task):
    env = gymnasium.make(GYM_IDS[task], render_mode="rgb_array", num_objects=2, image_size=48)
    obs, _ = env.reset(seed=4)
    assert env.observation_space.contains(obs)
    assert env.observation_space["object_shape"].shape == obs["object_shape"].shape == (2, 8)
    assert env.render().shape == (48, 48, 3)
    obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs) and not terminated and not truncated
    again, _ = env.reset(seed=4)
    first, _ = gymnasium.make(GYM_IDS[task], num_objects=2, image_size=48).reset(seed=4)
    np.testing.assert_array_equal(again["pixels"], first["pixels"])
    env.close()


def _project(physics, camera, points):
    """Pixel coordinates in [0, 1] of world points seen by a named camera (pinhole model)."""
    cam = physics.model.name2id(camera, "camera")
    pos, rot = physics.data.cam_xpos[cam], physics.data.cam_xmat[cam].reshape(3, 3)
    local = (points - pos) @ rot  # camera frame: x right, y up, looking along -z
    scale = np.tan(np.radians(physics.model.cam_fovy[cam]) / 2)
    u = 0.5 + 0.5 * local[:, 0] / (-local[:, 2] * scale)
    v = 0.5 - 0.5 * local[:, 1] / (-local[:, 2] * scale)
    return np.stack([u, v], axis=1)


@pytest.mark.parametrize("task", [pytest.param(t, marks=_maybe_ycb(t)) for t in ("blocks", "ycb")])
def test_cameras_frame_the_whole_workspace(task):
    env = make_dm_env(task=task, num_objects=1, seed=0)
    env.reset()
    ws = env.task.workspace
    corners = np.array([[x, y, ws.table_height] for x in (-1, 1) for y in (-1, 1)], dtype=float)
    corners[:, :2] *= ws.half_size
    for camera in ("top", "side"):
        uv = _project(env.physics, camera, corners)
        assert np.all((uv > 0.0) & (uv < 1.0)), (camera, uv)


@pytest.mark.parametrize("geometry", ["train", "gen"])
def test_runtime_block_mass_properties_match_mujoco_compiler(geometry):
    import mujoco

    from kinet_rl.envs.blocks import BLOCK_DENSITY

    env = make_dm_env(num_objects=2, geometry=geometry, seed=5)
    env.reset()
    model = env.physics.model
    for body in env.task.active:
        body_id = model.name2id(body, "body")
        geoms = [model.name2id(f"{body}_{s}", "geom") for s in "ab"]
        boxes = "".join(
            f'<geom type="box" size="{" ".join(map(str, model.geom_size[g]))}" '
            f'pos="{" ".join(map(str, model.geom_pos[g]))}" density="{BLOCK_DENSITY}"/>'
            for g in geoms
        )
        reference = mujoco.MjModel.from_xml_string(
            f'<mujoco><worldbody><body name="b"><freejoint/>{boxes}</body></worldbody></mujoco>'
        )
        assert model.body_mass[body_id] == pytest.approx(reference.body_mass[1], rel=1e-9)
        np.testing.assert_allclose(reference.body_ipos[1], 0.0, atol=1e-9)  # COM at the origin
        np.testing.assert_allclose(
            np.sort(model.body_inertia[body_id]), np.sort(reference.body_inertia[1]), rtol=1e-6
        )


@needs_ycb
@pytest.mark.parametrize("camera", ["top", "side"])
def test_every_image_corner_sees_the_ycb_table(camera: str) -> None:
    corners = torch.tensor(list(itertools.product((-1.0, 1.0), repeat=2)))
    projection = camera_projection("ycb", camera)
    on_table = projection.to_plane(corners, workspace_for("ycb").table_height)
    assert (on_table.abs() < workspace_for("ycb").table_half_size).all(), on_table


@needs_ycb
@pytest.mark.parametrize("camera", ["top", "side"])
def test_the_reach_of_the_pushes_is_in_the_ycb_image(camera: str) -> None:
    view = CAMERA_FRAMINGS["ycb"].top_view
    corners = [(x, y, 0.0) for x, y in itertools.product((-view, view), repeat=2)]
    if camera == "side":
        corners.append((0.0, view, 0.1))  # the top of a tall object at the far edge
    uv = camera_projection("ycb", camera).to_image(torch.tensor(corners))
    assert (uv.abs() <= 1.0 + 1e-4).all(), uv
    if camera == "side":  # fitted: the square is as large as the image allows
        assert uv.abs().max() > 0.99


@needs_ycb
def test_the_reach_fills_most_of_the_side_image_height() -> None:
    # The framing before this one (camera aimed at the table centre, floor in the top third)
    # gave the square ~50% of the image height.
    view = CAMERA_FRAMINGS["ycb"].top_view
    edges = torch.tensor([[0.0, -view, 0.0], [0.0, view, 0.0]])
    uv = camera_projection("ycb", "side").to_image(edges)
    assert (uv[0, 1] - uv[1, 1]) / 2 > 0.6


def _write_cube_folder(root, half_extents: dict[str, float]) -> None:
    """An object folder of the documented layout with one textured cube per name."""
    from PIL import Image

    signs = list(itertools.product((-1, 1), repeat=3))
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1)]
    faces += [(2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    entries = []
    for name, h in half_extents.items():
        (root / name).mkdir(parents=True)
        vertices = "".join(f"v {sx * h} {sy * h} {sz * h}\n" for sx, sy, sz in signs)
        uv = "vt 0 0\nvt 1 0\nvt 1 1\n"
        (root / name / "visual.obj").write_text(
            vertices + uv + "".join(f"f {a + 1}/1 {b + 1}/2 {c + 1}/3\n" for a, b, c in faces)
        )
        (root / name / "collision_00.obj").write_text(
            vertices + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)
        )
        Image.new("RGB", (8, 8), (200, 40, 40)).save(root / name / "texture.png")
        entries.append(
            {
                "name": name,
                "visual_mesh": f"{name}/visual.obj",
                "texture": f"{name}/texture.png",
                "collision_meshes": [f"{name}/collision_00.obj"],
                "collision_density_kg_m3": 400.0,
                "half_extents_m": [h, h, h],
            }
        )
    (root / "manifest.json").write_text(json.dumps({"objects": entries}))


def test_any_object_folder_of_the_documented_layout_can_be_pushed(tmp_path):
    _write_cube_folder(tmp_path, {"small_cube": 0.03, "big_cube": 0.05})
    env = make_dm_env(task="ycb", num_objects=2, seed=0, ycb_dir=tmp_path, image_size=32)
    ts = env.reset()
    assert set(env.task.active) == {"ycb_small_cube", "ycb_big_cube"}
    assert ts.observation["pixels"].shape == (32, 32, 3)
    pos0 = ts.observation["object_pos"]
    target = pos0[0]
    direction = -np.sign(target[0]) or 1.0  # push towards the centre
    start = target - direction * np.array([0.12, 0.0])
    end = target + direction * np.array([0.06, 0.0])
    ws = env.task.workspace
    ts = env.step(np.concatenate([ws.to_action(start), ws.to_action(end)]))
    assert not env.task.unstable
    assert (ts.observation["object_pos"][0, 0] - pos0[0, 0]) * direction > 0.03


@needs_ycb
def test_random_push_collection_discards_at_most_two_percent_of_ycb_episodes():
    """100 episodes (seeds 0-99) of 60 collection-policy pushes with 3 of the 12 YCB objects."""
    from kinet_rl.data.policy import RandomPushPolicy

    episodes, seen, discarded = 100, collections.Counter(), collections.Counter()
    for seed in range(episodes):
        env = make_dm_env(task="ycb", num_objects=3, seed=seed, image_size=16)
        ts, task = env.reset(), env.task
        policy, rng = RandomPushPolicy(task.workspace.half_size), np.random.default_rng(seed)
        for _ in range(60):
            pushes_at = ts.observation["object_pos"] / task.workspace.half_size
            ts = env.step(policy.sample_push(rng, pushes_at))
            if task.unstable:
                break
        seen.update(task.active)
        if task.unstable:
            discarded.update(task.active)
        env.close()
    discarded_episodes = sum(discarded.values()) / 3  # a discarded episode counts its 3 objects
    assert discarded_episodes <= 0.02 * episodes, dict(discarded)
    assert max(discarded.values(), default=0) <= 1, (
        f"objects in discarded episodes: {dict(discarded)}"
    )
    assert len(seen) == 12  # every object was drawn


@pytest.mark.parametrize("task", [pytest.param(t, marks=_maybe_ycb(t)) for t in ("blocks", "ycb")])
def test_collected_shapes_are_the_geometry_each_episode_drew(task, tmp_path):
    """The stored ``object_shape`` of each episode equals the objects the env drew for it: the
    blocks' two cuboids read back from the compiled model, a YCB object's footprint twice."""
    from kinet_rl.data import collect_dataset, load_dataset
    from kinet_rl.data.collection import seeded_env

    config = {"task": task, "num_objects": 3, "image_size": 16, "max_steps": 2}
    env_fn = functools.partial(make_env, **config)
    path = collect_dataset(
        env_fn, config, root=tmp_path, name=task, num_episodes=2, seed=5, num_workers=1,
        splits={"train": 1.0}, progress=False,
    )  # fmt: skip
    data = load_dataset(path, "all")
    shapes = []
    for episode in range(2):
        env = seeded_env(env_fn, 5, episode, 1)
        env.reset()
        dm = env.base_env._env
        model, push = dm.physics.model, dm.task
        expected = []
        for body in push.active:
            if push.ycb_objects is None:
                boxes = [(model.name2id(f"{body}_{g}", "geom")) for g in "ab"]
                box = [np.r_[model.geom_pos[g, :2], model.geom_size[g, :2]] for g in boxes]
            else:
                half = push.ycb_objects[push.layout.object_bodies.index(body)].half_extents
                box = [np.r_[0.0, 0.0, half[:2]]] * 2
            expected.append(np.concatenate(box))
        env.close()
        stored = data.transitions(torch.tensor([episode]), torch.tensor([1]))["object_shape"][0]
        np.testing.assert_allclose(stored.numpy(), np.stack(expected), rtol=1e-6, atol=1e-7)
        shapes.append(stored)
    assert not torch.equal(shapes[0], shapes[1])  # drawn per episode
