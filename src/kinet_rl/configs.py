"""Where the Hydra configs of the entry points live: ``conf/`` of the source tree or of the wheel."""

from __future__ import annotations

from pathlib import Path

PACKAGE = Path(__file__).resolve().parent
#: An installed wheel's copy of ``conf/`` (the build puts it there), then a checkout's ``conf/``.
CONFIG_DIRS = (PACKAGE / "conf", PACKAGE.parents[1] / "conf")


def config_dir() -> str:
    """The folder of ``config.yaml`` and the config groups, for ``@hydra.main(config_path=...)``.

    An installed wheel carries ``kinet_rl/conf``; a source checkout and an editable install use
    the top-level ``conf/`` beside ``src/``.

    Raises:
        FileNotFoundError: Neither is there (e.g. a package copied without its configs).
    """
    for path in CONFIG_DIRS:
        if (path / "config.yaml").is_file():
            return str(path)
    raise FileNotFoundError(
        f"kinet_rl's Hydra configs are in none of {[str(p) for p in CONFIG_DIRS]}; install "
        "kinet_rl from its wheel or a clone (pip install kinet_rl, pip install ., or pip install "
        "-e . in the clone) instead of copying the package folder."
    )
