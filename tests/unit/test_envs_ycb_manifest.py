"""Unit tests of YCB manifest loading and its error messages (no MuJoCo, no assets needed)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from kinet_rl.envs.ycb import YCB_DIR_ENV, YcbManifestError, load_ycb_objects


def _write_folder(root, entries):
    root.mkdir(exist_ok=True)
    for entry in entries:
        for key in ("visual_mesh", "texture"):
            (root / entry[key]).parent.mkdir(parents=True, exist_ok=True)
            (root / entry[key]).write_text("x")
        for path in entry["collision_meshes"]:
            (root / path).write_text("x")
    (root / "manifest.json").write_text(json.dumps({"objects": entries}))
    return root


def _entry(name="001_cube"):
    return {
        "name": name,
        "visual_mesh": f"{name}/visual.obj",
        "texture": f"{name}/texture.png",
        "collision_meshes": [f"{name}/collision_00.obj"],
        "collision_density_kg_m3": 500.0,
        "half_extents_m": [0.03, 0.03, 0.02],
    }


def test_valid_folder_loads_with_absolute_paths_and_subset(tmp_path):
    root = _write_folder(tmp_path / "ycb", [_entry("001_cube"), _entry("002_box")])
    objects = load_ycb_objects(root)
    assert [o.name for o in objects] == ["001_cube", "002_box"]
    assert objects[0].visual_mesh.is_absolute() and objects[0].rest_height == pytest.approx(0.02)
    np.testing.assert_allclose(objects[1].half_extents, [0.03, 0.03, 0.02])
    assert [o.name for o in load_ycb_objects(root, ["002_box"])] == ["002_box"]


def test_env_var_is_used_and_its_absence_explained(tmp_path, monkeypatch):
    root = _write_folder(tmp_path / "ycb", [_entry()])
    monkeypatch.setenv(YCB_DIR_ENV, str(root))
    assert load_ycb_objects()[0].name == "001_cube"
    monkeypatch.delenv(YCB_DIR_ENV)
    with pytest.raises(YcbManifestError, match=f"{YCB_DIR_ENV} is not set.*ycbbenchmarks"):
        load_ycb_objects()


def test_missing_manifest(tmp_path):
    with pytest.raises(YcbManifestError, match="has no manifest.json.*ycbbenchmarks"):
        load_ycb_objects(tmp_path)


def test_invalid_json_and_empty_objects(tmp_path):
    (tmp_path / "manifest.json").write_text("{not json")
    with pytest.raises(YcbManifestError, match="not valid JSON"):
        load_ycb_objects(tmp_path)
    (tmp_path / "manifest.json").write_text(json.dumps({"objects": []}))
    with pytest.raises(YcbManifestError, match="non-empty 'objects' list"):
        load_ycb_objects(tmp_path)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"half_extents_m": None}, r"lacks \['half_extents_m'\]"),
        ({"half_extents_m": [0.1, 0.1]}, "3 positive numbers"),
        ({"collision_meshes": []}, "non-empty list"),
        ({"collision_density_kg_m3": -1.0}, "must be positive"),
    ],
)
def test_malformed_entries_name_the_problem(tmp_path, change, message):
    entry = _entry()
    root = _write_folder(tmp_path / "ycb", [entry])
    bad = {**entry, **change}
    bad = {k: v for k, v in bad.items() if v is not None}
    (root / "manifest.json").write_text(json.dumps({"objects": [bad]}))
    with pytest.raises(YcbManifestError, match=message):
        load_ycb_objects(root)


def test_missing_files_and_unknown_names(tmp_path):
    root = _write_folder(tmp_path / "ycb", [_entry()])
    (root / "001_cube" / "texture.png").unlink()
    with pytest.raises(YcbManifestError, match=r"files not found: \['001_cube/texture.png'\]"):
        load_ycb_objects(root)
    root = _write_folder(tmp_path / "ycb2", [_entry()])
    with pytest.raises(YcbManifestError, match=r"Unknown YCB objects \['999_ghost'\].*001_cube"):
        load_ycb_objects(root, ["999_ghost"])
