"""Where the Hydra configs of the entry points live (``conf/`` beside ``src/``)."""

from __future__ import annotations

from pathlib import Path


def config_dir() -> str:
    """The ``conf/`` folder of the source tree, for ``@hydra.main(config_path=...)``.

    Raises:
        FileNotFoundError: The package was installed without its source tree (e.g. from a wheel).
    """
    path = Path(__file__).resolve().parents[2] / "conf"
    if not (path / "config.yaml").is_file():
        raise FileNotFoundError(
            f"kinet_rl's Hydra configs are not at {path}; install kinet_rl from a clone "
            "(pip install -e .) so that conf/ sits beside src/."
        )
    return str(path)
