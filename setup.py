"""Build step of the wheel: the Hydra configs of the top-level ``conf/`` go in as ``kinet_rl/conf``.

``conf/`` stays the one source of the configs: a source checkout and an editable install read it
where it is (beside ``src/``), an installed wheel reads its copy; ``kinet_rl.configs.config_dir()``
finds either. Everything else about the package is in ``pyproject.toml``.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

CONF = Path(__file__).resolve().parent / "conf"


class BuildPyWithConfigs(build_py):
    """``build_py`` that also copies ``conf/`` into the built package (editable installs skip it)."""

    def run(self) -> None:
        super().run()
        if self.editable_mode:
            return
        target = Path(self.build_lib) / "kinet_rl" / "conf"
        shutil.rmtree(target, ignore_errors=True)  # no stale file of an earlier build
        shutil.copytree(CONF, target, ignore=shutil.ignore_patterns("__pycache__"))


setup(cmdclass={"build_py": BuildPyWithConfigs})
