"""Model folders (Hugging Face layout): ``save_pretrained``/``from_pretrained`` for KINet and the
baselines, their errors up front, the shipped model offline, and the Hub through a fake client."""

from __future__ import annotations

import json
import socket
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch

from conftest import BASELINES
from kinet_rl.atomic import CheckpointError
from kinet_rl.envs import SceneSettings
from kinet_rl.models import KINetWorldModel, model_card, pretrained_names
from kinet_rl.models import hub as hub_module
from kinet_rl.models.checkpointing import checkpoint_scene
from kinet_rl.models.hub import (
    MODEL_FILES,
    HubExtraMissingError,
    ModelCardError,
    ModelFolderExistsError,
    ModelSceneError,
    NotAModelFolderError,
    read_card,
)
from kinet_rl.models.pretrained import pretrained_path, resolve_checkpoint
from kinet_rl.planners import VALIDATED_PLANNER, PlanningDefaults
from kinet_rl.rows import load_trained_model

SCENE = SceneSettings(task="ycb", camera="side", image_size=32, num_objects=4)
CARD = {
    "name": "tiny",
    "command": "python -m kinet_rl.train +exp=smoke",
    "seed": 3,
    "data": "none (untrained)",
    "training": {"hardware": "1 CPU core", "wall_time_s": 0},
    "metrics": {"forward_error_mm": {"1": 9.5}},
    "intended_use": "tests",
    "limits": "untrained",
}


def assert_same_model(loaded, model) -> None:
    assert type(loaded) is type(model) and not loaded.training
    assert loaded.config == model.config
    assert loaded.scene == model.scene and loaded.planning == model.planning
    expected, actual = model.state_dict(), loaded.state_dict()
    assert list(actual) == list(expected)
    for name, value in expected.items():
        assert torch.equal(actual[name], value) and actual[name].dtype == value.dtype, name


def test_kinet_round_trip_keeps_weights_scene_planning_and_card(tiny_kinet, tmp_path) -> None:
    model = tiny_kinet()
    model.planning = PlanningDefaults("keypoints_distance", {**VALIDATED_PLANNER, "top_k": 3})
    model.scene = SCENE
    folder = model.save_pretrained(tmp_path / "tiny", card=CARD)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tiny"]  # no temporary folder left
    assert sorted(p.name for p in folder.iterdir()) == sorted(MODEL_FILES)
    assert_same_model(KINetWorldModel.from_pretrained(folder), model)
    assert_same_model(load_trained_model(folder), model)  # the class from config.json
    assert checkpoint_scene(folder) == SCENE
    card = read_card(folder)
    assert card == {
        **CARD,
        "model": "KINetWorldModel",
        "scene": SCENE.as_dict(),
        "planning": json.loads(json.dumps(model.planning.as_dict())),
    }
    text = (folder / "README.md").read_text()
    assert text.startswith("---\nlibrary_name: kinet_rl\nlicense: mit\ntags:\n")
    assert "## Intended use\n\ntests" in text and "- wall_time_s: 0" in text


@pytest.mark.parametrize("name", BASELINES)
def test_baseline_round_trip_keeps_weights_scene_and_planning(
    name, tiny_baseline, tmp_path
) -> None:
    model = tiny_baseline(name).eval()
    model.scene = SceneSettings(image_size=32)
    folder = model.save_pretrained(tmp_path / name)
    assert_same_model(type(model).from_pretrained(folder), model)
    assert_same_model(load_trained_model(folder), model)
    assert read_card(folder)["model"] == type(model).__name__


def test_an_old_pt_checkpoint_still_loads_everywhere(tiny_kinet, tmp_path) -> None:
    model = tiny_kinet()
    model.save_checkpoint(tmp_path / "kinet.pt", SCENE)
    model.scene = SCENE
    assert_same_model(KINetWorldModel.from_checkpoint(tmp_path / "kinet.pt").eval(), model)
    assert_same_model(load_trained_model(tmp_path / "kinet.pt"), model)
    assert checkpoint_scene(tmp_path / "kinet.pt") == SCENE


def test_saving_into_a_folder_with_files_is_refused_and_touches_nothing(
    tiny_kinet, tmp_path
) -> None:
    model = tiny_kinet()
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "notes.txt").write_text("mine")
    with pytest.raises(ModelFolderExistsError, match="holds files"):
        model.save_pretrained(tmp_path / "run")
    assert [p.name for p in (tmp_path / "run").iterdir()] == ["notes.txt"]
    (tmp_path / "file").write_text("x")
    with pytest.raises(ModelFolderExistsError, match="is a file"):
        model.save_pretrained(tmp_path / "file")
    (tmp_path / "empty").mkdir()
    model.save_pretrained(tmp_path / "empty")  # an empty folder is fine
    with pytest.raises(ModelFolderExistsError):
        model.save_pretrained(tmp_path / "empty")  # ... once


def test_a_failed_write_leaves_nothing_behind(tiny_kinet, tmp_path, monkeypatch) -> None:
    def fail(path, text):
        raise OSError("disk gone")

    monkeypatch.setattr(hub_module, "atomic_write_text", fail)
    with pytest.raises(OSError, match="disk gone"):
        tiny_kinet().save_pretrained(tmp_path / "model")
    assert list(tmp_path.iterdir()) == []


def test_a_config_that_does_not_fit_the_weights_is_refused(tiny_kinet, tmp_path) -> None:
    model = tiny_kinet()
    model.config["hidden_dim"] = 32  # edited after construction
    with pytest.raises(CheckpointError, match="do not fit its config"):
        model.save_pretrained(tmp_path / "edited")
    assert not (tmp_path / "edited").exists()
    model.config["hidden_dim"] = 16
    folder = model.save_pretrained(tmp_path / "model")
    config = json.loads((folder / "config.json").read_text())
    config["model_config"]["channels"] = 16
    (folder / "config.json").write_text(json.dumps(config))
    with pytest.raises(CheckpointError, match="do not fit its model config"):
        KINetWorldModel.from_pretrained(folder)
    with pytest.raises(CheckpointError, match="num_keypoints: expected 6, checkpoint 4"):
        KINetWorldModel.from_pretrained(folder, expected_config={"num_keypoints": 6})


def test_a_scene_that_cannot_be_built_is_refused(tiny_kinet, tmp_path) -> None:
    model = tiny_kinet()
    with pytest.raises(ModelSceneError, match="model card names a scene .*camera"):
        model.save_pretrained(tmp_path / "bad", card={"scene": {"camera": "fisheye"}})
    assert not (tmp_path / "bad").exists()
    with pytest.raises(ModelCardError, match="scene"):
        model.save_pretrained(tmp_path / "other", SCENE, card={"scene": {"image_size": 64}})
    folder = model.save_pretrained(tmp_path / "model", card={"scene": SCENE.as_dict()})
    assert KINetWorldModel.from_pretrained(folder).scene == SCENE  # the card's scene, kept
    config = json.loads((folder / "config.json").read_text())
    config["scene"]["num_objects"] = 9
    (folder / "config.json").write_text(json.dumps(config))
    with pytest.raises(ModelSceneError, match="cannot be built.*num_objects"):
        KINetWorldModel.from_pretrained(folder)


def test_a_card_that_contradicts_the_model_is_refused(tiny_kinet, tmp_path) -> None:
    model = tiny_kinet()
    with pytest.raises(ModelCardError, match="objective='graph'"):
        model.save_pretrained(tmp_path / "a", card={"planning": {"objective": "graph"}})
    with pytest.raises(ModelCardError, match="model='VCDNWorldModel'"):
        model.save_pretrained(tmp_path / "b", card={"model": "VCDNWorldModel"})
    with pytest.raises(ModelCardError, match="JSON"):
        model.save_pretrained(tmp_path / "c", card={"seed": object()})
    assert list(tmp_path.iterdir()) == []


def test_a_folder_that_is_not_a_model_is_refused(tiny_kinet, tmp_path) -> None:
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "kinet.pt").write_bytes(b"")
    with pytest.raises(NotAModelFolderError, match="not a kinet_rl model folder.*config.json"):
        KINetWorldModel.from_pretrained(tmp_path / "run")
    with pytest.raises(NotAModelFolderError, match="not a kinet_rl model folder"):
        load_trained_model(tmp_path / "run")
    folder = tiny_kinet().save_pretrained(tmp_path / "model")
    (folder / "model.safetensors").write_bytes(b"\x00" * 64)
    with pytest.raises(CheckpointError, match="corrupt or truncated"):
        KINetWorldModel.from_pretrained(folder)
    (folder / "config.json").write_text("{not json")
    with pytest.raises(CheckpointError, match="not valid JSON"):
        KINetWorldModel.from_pretrained(folder)
    with pytest.raises(ValueError, match="no shipped model .*blocks_topview"):
        KINetWorldModel.from_pretrained("no_such_model")


def test_a_model_of_another_class_names_the_class_to_use(tiny_baseline, tmp_path) -> None:
    folder = tiny_baseline("forw").save_pretrained(tmp_path / "forw")
    with pytest.raises(CheckpointError, match="load it with ImageForwardModel"):
        KINetWorldModel.from_pretrained(folder)


def test_the_shipped_model_loads_offline_and_plans_as_its_card_says(monkeypatch) -> None:
    def no_network(*args, **kwargs):
        raise AssertionError("the shipped model touched the network")

    monkeypatch.setattr(socket.socket, "connect", no_network)
    monkeypatch.setattr(socket, "create_connection", no_network)
    monkeypatch.setitem(sys.modules, "huggingface_hub", None)  # no Hub client either
    assert "blocks_topview" in pretrained_names()
    model = KINetWorldModel.from_pretrained("blocks_topview")
    card = model_card("blocks_topview")
    config = json.loads((pretrained_path("blocks_topview") / "config.json").read_text())
    planning = {key: card["planning"][key] for key in ("objective", "planner")}
    assert config["planning"] == planning == model.planning.as_dict()
    assert model.planning.objective == "keypoints_l2"
    assert model.scene == SceneSettings.from_mapping(card["scene"]) == SceneSettings()
    assert card["name"] == "blocks_topview" and card["model"] == "KINetWorldModel"
    assert {"command", "data", "seed", "metrics", "intended_use", "limits"} <= set(card)
    folder = resolve_checkpoint("pretrained:blocks_topview")
    assert type(load_trained_model(folder)) is KINetWorldModel


class FakeHub:
    """A stand-in for the ``huggingface_hub`` module: a Hub of local folders."""

    def __init__(self, repos: dict[str, Path]) -> None:
        self.repos = repos
        self.calls: list[tuple] = []
        self.uploaded: dict[str, dict[str, bytes]] = {}
        hub = self

        class HfApi:
            def __init__(self, token=None) -> None:
                hub.calls.append(("HfApi", token))

            def create_repo(self, repo_id, private=None, exist_ok=False):
                hub.calls.append(("create_repo", repo_id, private, exist_ok))

            def upload_folder(self, *, repo_id, folder_path, commit_message):
                files = {p.name: p.read_bytes() for p in Path(folder_path).iterdir()}
                hub.uploaded[repo_id] = files
                return SimpleNamespace(commit_message=commit_message)

        self.HfApi = HfApi

    def snapshot_download(self, repo_id, revision=None, token=None, allow_patterns=None, **_):
        self.calls.append(("snapshot_download", repo_id, revision, tuple(allow_patterns)))
        return str(self.repos[repo_id])


def test_push_to_hub_uploads_the_saved_folder(tiny_kinet, tmp_path, monkeypatch) -> None:
    fake = FakeHub({})
    monkeypatch.setitem(sys.modules, "huggingface_hub", fake)
    model = tiny_kinet()
    info = model.push_to_hub("me/tiny-kinet", scene=SCENE, card=CARD, private=True, token="t")
    assert info.commit_message == "Upload kinet_rl model"
    assert ("create_repo", "me/tiny-kinet", True, True) in fake.calls
    assert ("HfApi", "t") in fake.calls
    files = fake.uploaded["me/tiny-kinet"]
    assert sorted(files) == sorted(MODEL_FILES)
    model.save_pretrained(tmp_path / "local", SCENE, CARD)
    for name, data in files.items():
        assert data == (tmp_path / "local" / name).read_bytes(), name


def test_from_pretrained_downloads_a_hub_repo_id(tiny_kinet, tmp_path, monkeypatch) -> None:
    model = tiny_kinet()
    model.scene = SCENE
    fake = FakeHub({"me/tiny-kinet": model.save_pretrained(tmp_path / "hub_cache")})
    monkeypatch.setitem(sys.modules, "huggingface_hub", fake)
    loaded = KINetWorldModel.from_pretrained("me/tiny-kinet", revision="v1")
    assert_same_model(loaded, model)
    assert fake.calls == [("snapshot_download", "me/tiny-kinet", "v1", MODEL_FILES)]


def test_the_hub_without_the_extra_says_how_to_install_it(tiny_kinet, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "huggingface_hub", None)
    with pytest.raises(HubExtraMissingError, match=r"pip install 'kinet_rl\[hub\]'"):
        KINetWorldModel.from_pretrained("me/tiny-kinet")
    with pytest.raises(HubExtraMissingError, match=r"pip install 'kinet_rl\[hub\]'"):
        tiny_kinet().push_to_hub("me/tiny-kinet")
