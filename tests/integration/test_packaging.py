"""The wheel ships the Hydra configs; a user's own experiment composes from their folder (slow).

``nox -s wheel`` (run by CI) installs the wheel in a fresh environment and runs every entry point
from an empty folder; these tests check the cheap parts of that here.
"""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]


def test_wheel_holds_every_config_and_module(tmp_path: Path) -> None:
    command = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--wheel-dir", str(tmp_path)]
    build = subprocess.run([*command, str(REPO)], capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, build.stdout[-2000:] + build.stderr[-2000:]
    (wheel,) = tmp_path.glob("kinet_rl-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    configs = {
        f"kinet_rl/conf/{p.relative_to(REPO / 'conf').as_posix()}" for p in _files(REPO / "conf")
    }
    assert "kinet_rl/conf/config.yaml" in configs and "kinet_rl/conf/exp/smoke.yaml" in configs
    assert configs <= names, f"configs missing from the wheel: {sorted(configs - names)}"
    shipped = {name for name in names if name.startswith("kinet_rl/conf/")}
    assert shipped == configs, f"files in the wheel's conf/ that conf/ lacks: {shipped - configs}"
    modules = {p.relative_to(REPO / "src").as_posix() for p in (REPO / "src").rglob("*.py")}
    assert modules <= names, f"modules missing from the wheel: {sorted(modules - names)}"
    weights_dir = REPO / "src" / "kinet_rl" / "models" / "weights"
    weights = {p.relative_to(REPO / "src").as_posix() for p in _files(weights_dir)}
    shipped_model = {
        f"kinet_rl/models/weights/blocks_topview/{name}"
        for name in ("config.json", "model.safetensors", "README.md")
    }
    assert shipped_model <= weights and weights <= names


def _files(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.is_file() and "__pycache__" not in p.parts]


@pytest.mark.parametrize("how", ["--config-dir", "hydra.searchpath"])
def test_own_experiment_file_composes_from_its_folder(tmp_path: Path, how: str) -> None:
    own = tmp_path / "my_configs"
    (own / "exp").mkdir(parents=True)
    (own / "exp" / "my_pushes.yaml").write_text(
        "# @package _global_\n"
        "defaults:\n  - smoke\n  - _self_\n"  # starts from a shipped experiment
        "exp_name: my_pushes\n"
        "trainer:\n  steps: 7\n"
    )
    search = ["--config-dir", str(own)] if how == "--config-dir" else [
        f"hydra.searchpath=[file://{own}]"
    ]  # fmt: skip
    command = [sys.executable, "-m", "kinet_rl.train", *search, "+exp=my_pushes", "--cfg", "job"]
    result = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    job = result.stdout
    assert "exp_name: my_pushes" in job
    assert "  steps: 7\n" in job  # the user's value
    assert "  name: smoke\n" in job  # data.name, from the shipped smoke experiment
