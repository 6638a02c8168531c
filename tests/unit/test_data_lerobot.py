"""LeRobot v3.0 export and import (kinet_rl.data.lerobot): the round trip keeps frames bit-exact
and pushes to 1e-6, object state only when stored and asked, named errors before any work, and
an export that refuses a non-empty target and leaves nothing half written."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow", reason="LeRobot import/export needs pyarrow ([lerobot] extra)")
pq = pytest.importorskip("pyarrow.parquet")

from fake_push_env import make_fake_env  # noqa: E402
from kinet_rl import import_data  # noqa: E402
from kinet_rl.data import collect_dataset, load_dataset  # noqa: E402
from kinet_rl.data.export_lerobot import main as export_main  # noqa: E402
from kinet_rl.data.importing import import_push_folder, plan_import  # noqa: E402
from kinet_rl.data.lerobot import (  # noqa: E402
    PAD_KEY,
    LeRobotVersionError,
    MissingFeatureError,
    MissingWorkspaceError,
    NotLeRobotDatasetError,
    TargetNotEmptyError,
    export_lerobot,
    read_lerobot,
)
from kinet_rl.data.push_folder import ActionWidthError  # noqa: E402
from kinet_rl.data.storage import open_episodes, read_json  # noqa: E402
from push_folders import HALF_SIZE, write_push_folder  # noqa: E402

CAMERA = "observation.images.top"


@pytest.fixture(scope="module")
def imported(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A dataset without object state: 6 episodes of 4 pushes, 64x64 px (from 16x16)."""
    root = tmp_path_factory.mktemp("robot")
    folder = write_push_folder(root / "pushes", width=16, height=16)
    plan = plan_import(folder)
    return import_push_folder(plan, root / "data", "robot", progress=False)


@pytest.fixture(scope="module")
def collected(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A simulated dataset with object state (fake env, 8 px, 3 objects)."""
    env_fn = functools.partial(make_fake_env, image_size=8, max_steps=4)
    config = {"task": "fake", "camera": "top", "image_size": 8}
    return collect_dataset(
        env_fn,
        config,
        root=tmp_path_factory.mktemp("sim"),
        name="sim",
        num_episodes=4,
        num_workers=1,
        seed=3,
        progress=False,
    )


def test_export_then_import_keeps_frames_and_pushes(imported: Path, tmp_path: Path) -> None:
    out = export_main([str(imported), str(tmp_path / "lerobot")])
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["codebase_version"] == "v3.0"
    assert info["kinet_rl"]["workspace_half_size"] == HALF_SIZE
    assert info["features"][CAMERA]["dtype"] == "image"
    assert info["features"]["action"]["shape"] == [4]
    for name in ("stats.json", "tasks.parquet", "episodes/chunk-000/file-000.parquet"):
        assert (out / "meta" / name).is_file()
    data = pq.read_table(out / "data" / "chunk-000" / "file-000.parquet")
    stored = open_episodes(imported)
    episodes, frames = stored["pixels"].shape[:2]
    assert data.num_rows == episodes * frames
    pad = np.asarray(data.column(PAD_KEY)).reshape(episodes, frames)
    assert pad[:, -1].all() and not pad[:, :-1].any()
    assert data.column(CAMERA)[0].as_py()["bytes"][:8] == b"\x89PNG\r\n\x1a\n"
    source = read_lerobot(out)
    assert source.workspace_half_size == HALF_SIZE and len(source) == episodes
    for episode, pixels, action in zip(source, stored["pixels"], stored["action"], strict=True):
        np.testing.assert_array_equal(episode.frames, pixels.numpy())
        np.testing.assert_allclose(episode.pushes / HALF_SIZE, action.numpy(), atol=1e-6)
    # and through the import command: the same dataset again
    path = import_data.main(
        [str(out), "--root", str(tmp_path / "data"), "--name", "back", "--image-size", "64"]
    )
    back = open_episodes(path)
    np.testing.assert_array_equal(back["pixels"].numpy(), stored["pixels"].numpy())
    np.testing.assert_allclose(back["action"].numpy(), stored["action"].numpy(), atol=1e-6)
    assert len(load_dataset(path, "train")) > 0


def test_object_state_only_when_stored_and_asked(
    imported: Path, collected: Path, tmp_path: Path
) -> None:
    def columns(source: Path, name: str, **kwargs: object) -> set[str]:
        out = export_lerobot(source, tmp_path / name, **kwargs)  # type: ignore[arg-type]
        info = json.loads((out / "meta" / "info.json").read_text())
        names = set(pq.read_schema(out / "data" / "chunk-000" / "file-000.parquet").names)
        assert names == set(info["features"])
        return {n for n in names if n.startswith("observation.state")}

    state = {"observation.state.object_pos", "observation.state.object_yaw"}
    assert columns(collected, "with") == state
    assert columns(collected, "without", include_object_state=False) == set()
    assert columns(imported, "none") == set()
    stored = open_episodes(collected)
    data = pq.read_table(tmp_path / "with" / "data" / "chunk-000" / "file-000.parquet")
    pos = np.asarray(data.column("observation.state.object_pos").combine_chunks().flatten())
    np.testing.assert_array_equal(pos, stored["object_pos"].numpy().reshape(-1))
    half = read_json(collected / "metadata.json")["workspace_half_size"]
    for episode, action in zip(read_lerobot(tmp_path / "with"), stored["action"], strict=True):
        np.testing.assert_allclose(episode.pushes, action.numpy() * half, atol=1e-6)


def edit_info(out: Path, edit) -> None:  # type: ignore[no-untyped-def]
    path = out / "meta" / "info.json"
    info = json.loads(path.read_text())
    edit(info)
    path.write_text(json.dumps(info))


def test_named_errors_before_any_work(imported: Path, tmp_path: Path) -> None:
    with pytest.raises(NotLeRobotDatasetError, match="meta/info.json"):
        read_lerobot(tmp_path)
    out = export_lerobot(imported, tmp_path / "lerobot")
    with pytest.raises(MissingFeatureError, match="observation.images.side"):
        read_lerobot(out, camera_key="observation.images.side")
    with pytest.raises(MissingFeatureError, match="'push'"):
        read_lerobot(out, action_key="push")
    edit_info(out, lambda info: info["kinet_rl"].pop("workspace_half_size"))
    with pytest.raises(MissingWorkspaceError, match="--workspace-half-size"):
        read_lerobot(out)
    assert read_lerobot(out, workspace_half_size=HALF_SIZE).workspace_half_size == HALF_SIZE
    edit_info(out, lambda info: info["features"]["action"].update(shape=[7]))
    with pytest.raises(ActionWidthError, match=r"\[7\]"):
        read_lerobot(out, workspace_half_size=HALF_SIZE)
    edit_info(out, lambda info: info.update(codebase_version="v2.1"))
    with pytest.raises(LeRobotVersionError, match="v2.1"):
        read_lerobot(out)
    with pytest.raises(SystemExit) as exit_info:
        import_data.main([str(out), "--root", str(tmp_path / "data")])
    assert exit_info.value.code == 2 and not (tmp_path / "data").exists()


def test_action_rows_of_the_wrong_width_are_refused(imported: Path, tmp_path: Path) -> None:
    out = export_lerobot(imported, tmp_path / "lerobot")
    file = out / "data" / "chunk-000" / "file-000.parquet"
    table = pq.read_table(file)
    wide = pa.FixedSizeListArray.from_arrays(pa.array(np.zeros(table.num_rows * 3, "f4")), 3)
    pq.write_table(table.set_column(table.schema.get_field_index("action"), "action", wide), file)
    with pytest.raises(ActionWidthError, match=r"\[3\]"):
        read_lerobot(out)


def test_export_refuses_a_non_empty_target_and_leaves_nothing_half_written(
    imported: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    target = tmp_path / "out"
    target.mkdir()
    (target / "keep.txt").write_text("mine")
    with pytest.raises(TargetNotEmptyError):
        export_lerobot(imported, target)
    assert [p.name for p in target.iterdir()] == ["keep.txt"]
    with pytest.raises(SystemExit):
        export_main([str(imported), str(target)])

    def fail(*args: object, **kwargs: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(pq, "write_table", fail)
    with pytest.raises(OSError, match="disk full"):
        export_lerobot(imported, tmp_path / "new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    monkeypatch.undo()
    empty = tmp_path / "empty"
    empty.mkdir()
    assert (export_lerobot(imported, empty) / "meta" / "info.json").is_file()
