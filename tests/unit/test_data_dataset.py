"""Loading datasets: batch contract, no duplicated frames, refusal of bad datasets, datasets of
variable object counts."""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from fake_push_env import FakePushEnv, make_fake_env
from kinet_rl.baselines import FullStateInteractionModel, ObjectInteractionModel
from kinet_rl.data import (
    DatasetCorruptError,
    DatasetIncompleteError,
    DatasetMismatchError,
    DatasetNotFoundError,
    PushDataset,
    collect_dataset,
    load_dataset,
)
from kinet_rl.data.storage import EPISODES_DIR, METADATA_FILE
from kinet_rl.envs.geometry import SceneGeometry
from kinet_rl.evaluation.forward import forward_errors, keypoint_accuracy, start_frames
from kinet_rl.models import KINetLoss
from kinet_rl.pipeline import check_dataset_for

H, T, N = 8, 4, 3
ENV_CONFIG = {"task": "fake", "camera": "top", "image_size": H}


def collect(root: Path, name: str, image_size: int = H, max_steps: int = T, **kwargs) -> Path:
    env_fn = functools.partial(make_fake_env, image_size=image_size, max_steps=max_steps)
    config = {**ENV_CONFIG, "image_size": image_size}
    return collect_dataset(
        env_fn, config, root=root, name=name, num_workers=1, seed=3, progress=False, **kwargs
    )


@pytest.fixture(scope="module")
def dataset_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return collect(tmp_path_factory.mktemp("data"), "ds", num_episodes=10, chunk_episodes=5)


def test_transition_batch_has_documented_keys_shapes_dtypes(dataset_path: Path) -> None:
    batch = load_dataset(dataset_path).sample(32, generator=torch.Generator().manual_seed(0))
    assert batch.batch_size == (32,)
    for key in ("pixels_0", "pixels", ("next", "pixels")):
        assert batch[key].shape == (32, H, H, 3) and batch[key].dtype == torch.uint8
    for key in ("object_pos", ("next", "object_pos")):
        assert batch[key].shape == (32, N, 2) and batch[key].dtype == torch.float32
    for key in ("object_yaw", ("next", "object_yaw")):
        assert batch[key].shape == (32, N) and batch[key].dtype == torch.float32
    assert batch["object_shape"].shape == (32, N, 8)
    assert torch.equal(batch["object_shape"][0], FakePushEnv(num_objects=N).object_shape())
    assert batch["action"].shape == (32, 4) and batch["action"].abs().max() <= 1
    assert batch["episode"].dtype == batch["step"].dtype == torch.int64
    assert batch["step"].max() < T


def test_transitions_chain_within_episodes(dataset_path: Path) -> None:
    data = load_dataset(dataset_path, "all")
    episode = torch.tensor([2, 2, 2])
    batch = data.transitions(episode, torch.tensor([0, 1, 2]))
    assert torch.equal(batch["next", "pixels"][:2], batch["pixels"][1:])
    assert torch.equal(batch["next", "object_pos"][:2], batch["object_pos"][1:])
    assert torch.equal(batch["pixels_0"], batch["pixels"][:1].expand(3, H, H, 3))
    stored = TensorDict.load_memmap(dataset_path / EPISODES_DIR)
    assert torch.equal(batch["pixels"], stored["pixels"][2, :3])
    assert torch.equal(batch["next", "pixels"], stored["pixels"][2, 1:4])
    assert torch.equal(batch["action"], stored["action"][2, :3])
    assert torch.equal(batch["next", "object_pos"], stored["object_pos"][2, 1:4])
    moved = (batch["next", "object_pos"] - batch["object_pos"]).abs().sum((-1, -2)) > 0
    changed = (batch["next", "pixels"] != batch["pixels"]).flatten(1).any(1)
    assert not (changed & ~moved).any()  # a frame changes only when an object moved


def test_sequence_batch_shapes_and_consistency(dataset_path: Path) -> None:
    data = load_dataset(dataset_path, "all")
    seq = data.sample_sequences(5, 3, generator=torch.Generator().manual_seed(1))
    assert seq["pixels"].shape == (5, 4, H, H, 3) and seq["action"].shape == (5, 3, 4)
    assert seq["object_pos"].shape == (5, 4, N, 2) and seq["pixels_0"].shape == (5, H, H, 3)
    step0 = data.transitions(seq["episode"], seq["step"])
    assert torch.equal(seq["pixels"][:, 0], step0["pixels"])
    assert torch.equal(seq["action"][:, 0], step0["action"])
    with pytest.raises(ValueError, match="length"):
        data.sample_sequences(2, T + 1)


def test_batches_visit_every_transition_once(dataset_path: Path) -> None:
    data = load_dataset(dataset_path, "train")
    seen = [
        (e, s)
        for b in data.batches(7, generator=torch.Generator().manual_seed(0))
        for e, s in zip(b["episode"].tolist(), b["step"].tolist(), strict=True)
    ]
    assert sorted(seen) == [(e, s) for e in range(8) for s in range(T)]


def test_frames_are_stored_once(tmp_path: Path) -> None:
    height, steps, episodes = 64, 20, 2
    path = collect(tmp_path, "big", image_size=height, max_steps=steps, num_episodes=episodes)
    on_disk = sum(f.stat().st_size for f in path.rglob("*") if f.is_file())
    one_image_per_step = episodes * steps * height * height * 3
    assert on_disk <= 1.1 * one_image_per_step


def test_missing_dataset_names_the_collect_command(tmp_path: Path) -> None:
    with pytest.raises(DatasetNotFoundError, match="python -m kinet_rl.collect"):
        load_dataset(tmp_path / "nothing")


def test_truncated_and_corrupt_datasets_are_refused(tmp_path: Path) -> None:
    path = collect(tmp_path, "ds", num_episodes=2)
    pixels = path / EPISODES_DIR / "pixels.memmap"
    with open(pixels, "r+b") as f:
        f.truncate(pixels.stat().st_size // 2)
    with pytest.raises(DatasetCorruptError, match="truncated or corrupt.*collect"):
        load_dataset(path)
    (path / METADATA_FILE).write_text("{not json")
    with pytest.raises(DatasetCorruptError, match="Cannot read"):
        load_dataset(path)


def test_damaged_metadata_and_array_index_are_refused(tmp_path: Path) -> None:
    path = collect(tmp_path, "ds", num_episodes=2)
    metadata = json.loads((path / METADATA_FILE).read_text())
    (path / METADATA_FILE).write_text(json.dumps([metadata]))
    with pytest.raises(DatasetCorruptError, match="a JSON list, not an object"):
        load_dataset(path)
    del metadata["image_size"]
    (path / METADATA_FILE).write_text(json.dumps(metadata))
    with pytest.raises(DatasetCorruptError, match=r"lacks \['image_size'\].*collect it again"):
        load_dataset(path)
    (path / METADATA_FILE).write_text(json.dumps({**metadata, "image_size": H}))
    (path / EPISODES_DIR / "meta.json").unlink()
    with pytest.raises(DatasetCorruptError, match="Cannot open the arrays.*collect it again"):
        load_dataset(path)


def test_partial_dataset_is_refused(tmp_path: Path) -> None:
    path = collect(tmp_path, "ds", num_episodes=2)
    (path / METADATA_FILE).unlink()
    with pytest.raises(DatasetIncompleteError, match="partial.*not marked complete"):
        load_dataset(path)


def test_mismatched_dataset_names_the_difference(dataset_path: Path) -> None:
    with pytest.raises(DatasetMismatchError, match="camera='top'.*camera='side'.*env.camera=side"):
        load_dataset(dataset_path, expect={"camera": "side", "image_size": H})
    with pytest.raises(DatasetMismatchError, match="image_size=8.*image_size=64"):
        load_dataset(dataset_path, expect={"image_size": 64})
    with pytest.raises(ValueError, match="does not record"):
        load_dataset(dataset_path, expect={"colour": "red"})
    assert load_dataset(dataset_path, expect=ENV_CONFIG).image_size == H


def test_metadata_records_provenance(dataset_path: Path) -> None:
    metadata = json.loads((dataset_path / METADATA_FILE).read_text())
    assert metadata["complete"] and metadata["seed"] == 3 and metadata["num_episodes"] == 10
    assert {"torch", "torchrl", "tensordict", "kinet_rl"} <= set(metadata["versions"])
    assert metadata["splits"] == {"train": [0, 8], "val": [8, 9], "test": [9, 10]}


def test_a_horizon_adds_the_following_pushes_and_frames(dataset_path: Path) -> None:
    data = load_dataset(dataset_path)
    batch = data.sample(6, torch.Generator().manual_seed(0), steps_per_episode=2, horizon=3)
    assert batch["future", "pixels"].shape == (6, 2, H, H, 3)
    assert batch["future", "action"].shape == (6, 2, 4)
    assert (batch["step"] <= T - 3).all()  # the whole window lies inside the episode
    seq = data.transitions(batch["episode"], batch["step"] + 1, horizon=2)
    assert torch.equal(seq["next", "pixels"], batch["future", "pixels"][:, 0])
    assert torch.equal(seq["action"], batch["future", "action"][:, 0])
    assert torch.equal(seq["future", "pixels"][:, 0], batch["future", "pixels"][:, 1])
    assert "future" not in data.sample(4, torch.Generator().manual_seed(0)).keys()  # noqa: SIM118
    with pytest.raises(ValueError, match="horizon must lie in"):
        data.sample(4, horizon=T + 1)


def test_episodes_in_memory_give_the_transitions_of_the_stored_dataset(dataset_path: Path) -> None:
    on_disk = load_dataset(dataset_path, "all")
    stored = TensorDict.load_memmap(dataset_path / EPISODES_DIR)
    in_memory = PushDataset.from_episodes(stored.to_tensordict())
    assert (in_memory.episode_length, in_memory.image_size, in_memory.num_objects) == (T, H, N)
    assert len(in_memory) == len(on_disk) and in_memory.path is None
    episode, step = torch.tensor([0, 3, 9, 9]), torch.tensor([0, 1, 1, 2])
    expected = on_disk.transitions(episode, step, horizon=2)
    assert (in_memory.transitions(episode, step, horizon=2) == expected).all()
    with pytest.raises(ValueError, match=r"TensorDict \[E\] with E >= 1"):
        PushDataset.from_episodes(stored[0].to_tensordict())


def as_old_format(path: Path) -> None:
    """Turns a dataset into what kinet_rl wrote before it stored ``object_shape``."""
    (path / EPISODES_DIR / "object_shape.memmap").unlink()
    index = json.loads((path / EPISODES_DIR / "meta.json").read_text())
    del index["object_shape"]
    (path / EPISODES_DIR / "meta.json").write_text(json.dumps(index))
    metadata = json.loads((path / METADATA_FILE).read_text())
    del metadata["arrays"]
    (path / METADATA_FILE).write_text(json.dumps(metadata))


def test_sequences_and_start_frames_carry_yaw_and_shape(dataset_path: Path) -> None:
    seq = load_dataset(dataset_path).sample_sequences(5, 3, torch.Generator().manual_seed(0))
    assert seq["object_yaw"].shape == (5, 4, N) and seq["object_shape"].shape == (5, N, 8)
    start = start_frames(seq)
    assert torch.equal(start["object_yaw"], seq["object_yaw"][:, 0])
    assert torch.equal(start["object_shape"], seq["object_shape"])


def test_an_old_dataset_without_shapes_loads_for_in_and_is_refused_for_in_full(
    tmp_path: Path,
) -> None:
    path = collect(tmp_path, "old", num_episodes=4)
    assert json.loads((path / METADATA_FILE).read_text())["arrays"][-2:] == [
        "object_shape",
        "source_episode",
    ]
    as_old_format(path)
    data = load_dataset(path, "all")
    batch = data.sample(8, torch.Generator().manual_seed(0))
    assert "object_shape" not in batch.keys() and batch["object_yaw"].shape == (8, N)  # noqa: SIM118
    check_dataset_for(ObjectInteractionModel(num_objects=N), data)
    ObjectInteractionModel(num_objects=N)(batch)  # IN trains on it
    with pytest.raises(DatasetMismatchError, match=r"needs \['object_shape'\].*old.*collect it"):
        check_dataset_for(FullStateInteractionModel(num_objects=N), data)
    (path / EPISODES_DIR / "action.memmap").write_bytes(b"")  # still checked
    with pytest.raises(DatasetCorruptError, match="action.memmap"):
        load_dataset(path)


def test_a_stored_shape_file_of_the_wrong_size_is_refused(tmp_path: Path) -> None:
    path = collect(tmp_path, "bad", num_episodes=4)
    (path / EPISODES_DIR / "object_shape.memmap").write_bytes(b"\0" * 12)
    with pytest.raises(DatasetCorruptError, match="object_shape.memmap has 12 bytes"):
        load_dataset(path)


@pytest.fixture(scope="module")
def variable_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """12 episodes of 1 to 3 objects (a count per chunk of 2), 16 px for a keypoint model."""
    root = tmp_path_factory.mktemp("data")
    return collect(
        root, "variable", image_size=16, num_episodes=12, chunk_episodes=2, num_objects_range=(1, 3)
    )


def test_a_variable_count_dataset_yields_kinet_training_batches(
    variable_path: Path, tiny_kinet
) -> None:
    data = load_dataset(variable_path, "train")
    assert data.num_objects == N and set(data.object_counts.tolist()) == {1, 2, 3}
    batch = data.sample(8, torch.Generator().manual_seed(0), horizon=2)
    assert batch["pixels"].shape == (8, 16, 16, 3) and batch["object_pos"].shape == (8, N, 2)
    assert batch["object_pos"].isnan().any()  # some sampled episodes hold fewer than N objects
    check_dataset_for(tiny_kinet(), data)
    losses = KINetLoss(tiny_kinet(), rollout_weight=1.0)(batch)
    assert all(torch.isfinite(losses[key]) for key in losses.keys())  # noqa: SIM118


def test_forward_errors_leave_the_missing_objects_out(variable_path: Path, tiny_kinet) -> None:
    data, model = load_dataset(variable_path, "all"), tiny_kinet()
    geometry = SceneGeometry.of_scene("blocks", "top", 16)
    errors = forward_errors(model.object_rollout(geometry), data, (1, 2), 16)
    assert all(math.isfinite(errors[h][key]) for h in (1, 2) for key in ("model", "no_motion"))
    assert 0 <= keypoint_accuracy(model, data, geometry, num_frames=16) <= 1


def test_models_that_need_one_object_count_refuse_a_variable_count_dataset(
    variable_path: Path, tiny_baseline
) -> None:
    data = load_dataset(variable_path)
    for name in ("in", "in_full", "visin", "forw"):
        model = tiny_baseline(name, num_objects=N, image_size=16)
        with pytest.raises(
            DatasetMismatchError,
            match=rf"{type(model).__name__} needs the same object count in every episode, but "
            rf"dataset .*variable holds 1 to 3 objects.*num_objects_range=null",
        ):
            check_dataset_for(model, data)


def test_a_variable_count_dataset_is_not_taken_for_a_fixed_count_one(variable_path: Path) -> None:
    with pytest.raises(DatasetMismatchError, match=r"data.num_objects_range=null"):
        load_dataset(variable_path, expect={"num_objects": N, "num_objects_range": None})
    load_dataset(variable_path, expect={"num_objects": N, "num_objects_range": [1, 3]})
