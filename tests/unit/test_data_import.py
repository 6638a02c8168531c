"""A robot's pushes: the plain push folder, its recorder (crash recovery) and its import into
episode storage (crop, resize, normalisation, windows, splits, checksums, resume), and each kind
of bad input refused by name before anything is written."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from kinet_rl import import_data
from kinet_rl.data import (
    ActionWidthError,
    DatasetMismatchError,
    FrameCountError,
    FrameSizeError,
    ImportSettings,
    NonFiniteActionError,
    NonSquareImageError,
    NotPushFolderError,
    OutsideWorkspaceError,
    PushRecorder,
    ShortEpisodeError,
    import_push_folder,
    load_dataset,
    plan_import,
    read_push_folder,
    verify_dataset,
)
from kinet_rl.data.storage import METADATA_FILE, PROGRESS_FILE, EpisodeWriter
from push_folders import HALF_SIZE, edit_meta, frame, rewrite_pushes_csv, write_push_folder


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    return write_push_folder(tmp_path / "robot")


def test_recorder_writes_the_documented_layout(folder: Path) -> None:
    meta = json.loads((folder / "meta.json").read_text())
    assert meta == {
        "format": "kinet_rl.push_folder",
        "version": 1,
        "workspace_half_size": HALF_SIZE,
        "units": "metres",
        "image_size": [40, 32],
        "camera": "test_camera",
    }
    episode = folder / "episode_000003"
    assert sorted(p.name for p in episode.iterdir()) == [
        *(f"frame_{i:06d}.png" for i in range(5)),
        "pushes.csv",
    ]
    lines = (episode / "pushes.csv").read_text().splitlines()
    assert lines[0] == "start_x,start_y,end_x,end_y" and len(lines) == 5  # 5 frames, 4 pushes
    assert np.array_equal(np.asarray(Image.open(episode / "frame_000002.png")), frame(3002))
    read = read_push_folder(folder)
    assert len(read.episodes) == 6 and read.image_size == (40, 32)
    pushes = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    assert np.allclose(read.episodes[3].pushes, pushes / HALF_SIZE)  # normalised


def test_recorder_recovers_the_episode_a_crash_interrupted(tmp_path: Path) -> None:
    root = tmp_path / "robot"
    recorder = PushRecorder(root, HALF_SIZE)
    for step in range(4):
        recorder.append(frame(step), [0.1, 0.0, -0.1, 0.05 * step])
    # The crash hit between a frame and its push row: frame 4 is stored, its row is not, and a
    # temporary file of the next frame is left behind.
    Image.fromarray(frame(4)).save(root / ".recording" / "frame_000004.png")
    (root / ".recording" / ".frame_000005.png.123.tmp").write_bytes(b"partial")
    resumed = PushRecorder(root, HALF_SIZE)
    assert resumed.num_episodes == 1 and not (root / ".recording").exists()
    episode = read_push_folder(root).episodes[0]
    assert len(episode.frames) == 4 and len(episode.pushes) == 3  # the last push is dropped
    assert np.allclose(episode.pushes[:, 3], [0.0, 0.2, 0.4])  # 0.05 * step / 0.25
    resumed.append(frame(10), [0.0, 0.0, 0.1, 0.1])
    resumed.close_episode(frame(11))
    assert [e.name for e in read_push_folder(root).episodes] == [
        "episode_000000",
        "episode_000001",
    ]
    resumed.append(frame(12), [0.0, 0.0, 0.1, 0.1])  # one step only: discarded after a crash
    PushRecorder(root, HALF_SIZE)
    assert len(read_push_folder(root).episodes) == 2 and not (root / ".recording").exists()


def test_recorder_refuses_bad_pushes_and_frames_before_writing(tmp_path: Path) -> None:
    recorder = PushRecorder(tmp_path / "robot", HALF_SIZE)
    for push, error in (
        ([0.0, 0.1, 0.2], ActionWidthError),
        ([0.0, float("nan"), 0.0, 0.0], NonFiniteActionError),
        ([0.0, 0.0, 0.3, 0.0], OutsideWorkspaceError),
    ):
        with pytest.raises(error):
            recorder.append(frame(0), push)
    recorder.append(frame(0), [0.0] * 4)
    with pytest.raises(FrameSizeError):
        recorder.append(frame(1, width=32), [0.0] * 4)
    assert recorder.open_frames == 1
    with pytest.raises(NotPushFolderError, match="workspace_half_size"):
        PushRecorder(tmp_path / "robot", 0.3)


def test_import_crops_resizes_normalises_and_splits_by_episode(
    folder: Path, tmp_path: Path
) -> None:
    plan = plan_import(folder, ImportSettings(image_size=16, crop="center", chunk_episodes=4))
    assert plan.box == (4, 0, 32)  # the centred 32 px square of 40x32 frames
    text = plan.describe()
    assert "crop 32x32 px at (left 4, top 0), resized to 16x16 px (box filter)" in text
    path = import_push_folder(plan, tmp_path / "data", "robot", progress=False)
    data = load_dataset(path, "all")
    assert not data.has_object_state and data.num_objects is None
    assert data.num_episodes == 6 and data.episode_length == 4 and data.image_size == 16
    source = read_push_folder(folder).episodes[2]
    expected = Image.open(source.frames[1]).crop((4, 0, 36, 32)).resize((16, 16), Image.BOX)
    batch = data.transitions(torch.tensor([2]), torch.tensor([1]))
    assert torch.equal(batch["pixels"][0], torch.from_numpy(np.array(expected)))
    assert torch.allclose(batch["action"][0], torch.from_numpy(source.pushes[1]))
    assert batch["action"].abs().max() <= 1
    metadata = json.loads((path / METADATA_FILE).read_text())
    assert metadata["splits"] == {"train": [0, 5], "val": [5, 5], "test": [5, 6]}
    assert metadata["workspace_half_size"] == HALF_SIZE and metadata["num_objects"] is None
    assert metadata["imported"]["camera"] == "test_camera"
    assert verify_dataset(path).verified
    assert import_push_folder(plan, tmp_path / "data", "robot", progress=False) == path


def test_long_episodes_are_cut_into_windows_split_with_their_episode(tmp_path: Path) -> None:
    root = write_push_folder(tmp_path / "robot", episodes=4, frames=7, width=16, height=16)
    plan = plan_import(root, ImportSettings(image_size=16, episode_length=2))
    assert plan.windows[:4] == ((0, 0), (0, 2), (0, 4), (1, 0))
    assert plan.num_episodes == 12 and plan.unused_pushes == 0
    splits = {"train": 0.5, "val": 0.25, "test": 0.25}
    plan = plan_import(root, ImportSettings(image_size=16, episode_length=4, splits=splits))
    assert plan.num_episodes == 4 and plan.unused_pushes == 8  # 6 pushes each: one window of 4
    assert plan.splits == {"train": [0, 2], "val": [2, 3], "test": [3, 4]}
    path = import_push_folder(plan, tmp_path / "data", "robot", progress=False)
    seq = load_dataset(path, "test").sample_sequences(1, 4)
    assert seq["episode"].item() == 3 and seq["pixels"].shape == (1, 5, 16, 16, 3)


def test_an_interrupted_import_resumes_to_the_same_dataset(
    folder: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    plan = plan_import(folder, ImportSettings(image_size=16, crop="center", chunk_episodes=2))
    whole = import_push_folder(plan, tmp_path / "whole", "robot", progress=False)
    commit = EpisodeWriter.commit

    def commit_once_then_die(self, *args, **kwargs):
        if self.committed >= 2:
            raise KeyboardInterrupt
        commit(self, *args, **kwargs)

    monkeypatch.setattr(EpisodeWriter, "commit", commit_once_then_die)
    with pytest.raises(KeyboardInterrupt):
        import_push_folder(plan, tmp_path / "cut", "robot", progress=False)
    progress = json.loads((tmp_path / "cut" / "robot" / PROGRESS_FILE).read_text())
    assert progress["committed"] == 2 and not (tmp_path / "cut" / "robot" / METADATA_FILE).exists()
    monkeypatch.setattr(EpisodeWriter, "commit", commit)
    resumed = import_push_folder(plan, tmp_path / "cut", "robot", progress=False)
    a, b = load_dataset(whole, "all"), load_dataset(resumed, "all")
    every = torch.arange(6)
    for step in range(4):
        first = a.transitions(every, torch.full((6,), step))
        second = b.transitions(every, torch.full((6,), step))
        assert (first == second).all()
    other = plan_import(folder, ImportSettings(image_size=20, crop="center"))
    with pytest.raises(DatasetMismatchError, match="another dataset"):
        import_push_folder(other, tmp_path / "cut", "robot", progress=False)


def run_import(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """Runs the command, expecting it to refuse the input: returns its error line."""
    with pytest.raises(SystemExit) as exit_info:
        import_data.main(argv)
    assert exit_info.value.code == 2
    return capsys.readouterr().err


def _wrong_width(root: Path) -> None:
    rewrite_pushes_csv(root / "episode_000001", [["0", "0", "0"]] * 4, "start_x,start_y,end_x")


def _wrong_width_json(root: Path) -> None:
    (root / "episode_000001" / "pushes.csv").unlink()
    (root / "episode_000001" / "pushes.json").write_text(json.dumps([[0, 0, 0, 0, 0]] * 4))


def _wrong_width_npz(root: Path) -> None:
    (root / "episode_000001" / "pushes.csv").unlink()
    np.savez(root / "episode_000001" / "pushes.npz", pushes=np.zeros((4, 2)))


def _nan(root: Path) -> None:
    rewrite_pushes_csv(
        root / "episode_000002", [["0", "0", "0", "0"]] * 3 + [["0", "nan", "0", "0"]]
    )


def _inf(root: Path) -> None:
    rewrite_pushes_csv(
        root / "episode_000002", [["0", "0", "0", "0"]] * 3 + [["inf", "0", "0", "0"]]
    )


def _one_frame(root: Path) -> None:
    episode = root / "episode_000004"
    for index in range(1, 5):
        (episode / f"frame_{index:06d}.png").unlink()
    rewrite_pushes_csv(episode, [])


def _counts_disagree(root: Path) -> None:
    rewrite_pushes_csv(root / "episode_000000", [["0", "0", "0", "0"]] * 5)  # 5 frames, 5 pushes


def _no_meta(root: Path) -> None:
    (root / "meta.json").unlink()


def _no_episodes(root: Path) -> None:
    for episode in root.glob("episode_*"):
        shutil.rmtree(episode)


def _frame_gap(root: Path) -> None:
    (root / "episode_000001" / "frame_000002.png").unlink()


def _two_pushes_files(root: Path) -> None:
    (root / "episode_000001" / "pushes.json").write_text(json.dumps([[0, 0, 0, 0]] * 4))


def _bad_header(root: Path) -> None:
    rewrite_pushes_csv(root / "episode_000001", [["0", "0", "0", "0"]] * 4, "a,b,c,d")


def _outside(root: Path) -> None:
    rewrite_pushes_csv(root / "episode_000003", [["0", "0", "0.26", "0"]] * 4)


def _outside_normalised(root: Path) -> None:
    edit_meta(root, units="normalised")  # the recorded metres read as normalised still fit...
    rewrite_pushes_csv(root / "episode_000003", [["0", "0", "1.5", "0"]] * 4)  # ...this does not


def _frame_size(root: Path) -> None:
    Image.fromarray(frame(0, width=32)).save(root / "episode_000002" / "frame_000001.png")


BAD_INPUT = {
    "actions of the wrong width (csv)": (_wrong_width, ActionWidthError),
    "actions of the wrong width (json)": (_wrong_width_json, ActionWidthError),
    "actions of the wrong width (npz)": (_wrong_width_npz, ActionWidthError),
    "a NaN action": (_nan, NonFiniteActionError),
    "an infinite action": (_inf, NonFiniteActionError),
    "an episode of one frame": (_one_frame, ShortEpisodeError),
    "frame and push counts that disagree": (_counts_disagree, FrameCountError),
    "no meta.json": (_no_meta, NotPushFolderError),
    "no episode folders": (_no_episodes, NotPushFolderError),
    "frames numbered with a gap": (_frame_gap, NotPushFolderError),
    "two pushes files": (_two_pushes_files, NotPushFolderError),
    "a csv header of other columns": (_bad_header, NotPushFolderError),
    "pushes outside the stated workspace": (_outside, OutsideWorkspaceError),
    "normalised pushes outside [-1, 1]": (_outside_normalised, OutsideWorkspaceError),
    "a frame of another size": (_frame_size, FrameSizeError),
}


@pytest.mark.parametrize("case", list(BAD_INPUT))
def test_bad_input_is_refused_by_name_before_anything_is_written(
    case: str, folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    damage, error = BAD_INPUT[case]
    damage(folder)
    with pytest.raises(error):
        plan_import(folder, ImportSettings(crop="center"))
    argv = [str(folder), "--root", str(tmp_path / "data"), "--crop", "center"]
    assert f"error: {error.__name__}:" in run_import(argv, capsys)
    assert not (tmp_path / "data").exists()  # nothing half written


def test_non_square_frames_need_a_crop_setting(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(NonSquareImageError, match="40x32 px, not square"):
        plan_import(folder)
    output = run_import([str(folder), "--root", str(tmp_path / "data")], capsys)
    assert "error: NonSquareImageError:" in output and "--crop center" in output
    assert "ConfigError" in run_import(
        [str(folder), "--root", str(tmp_path / "data"), "--crop", "20,0,32"], capsys
    )  # a box outside the frames
    assert not (tmp_path / "data").exists()


def test_the_command_says_what_it_does_and_imports(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = import_data.main(
        [str(folder), "--root", str(tmp_path), "--crop", "center", "--image-size", "16"]
    )
    output = capsys.readouterr().out
    assert path == tmp_path / "robot" and load_dataset(path, "train").num_episodes == 5
    assert "resized to 16x16 px" in output
    assert output.rstrip().endswith(  # episodes of 4 pushes: horizons that fit them
        f"python -m kinet_rl.train data.root={tmp_path} data.name=robot env.image_size=16 "
        "report.horizons=[1,4]"
    )
