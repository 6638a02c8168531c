"""Collect random-push datasets: ``python -m kinet_rl.collect [+exp=<name>] [overrides]``.

Collects ``data.name`` and then each ``data.generalization`` set under ``data.root``
(relative to the working directory; Hydra does not change it). Rerunning the same command
resumes interrupted datasets and skips complete ones.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, cast

import hydra
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from kinet_rl.data import collect_dataset

logger = logging.getLogger(__name__)

CONF_DIR = str(Path(__file__).resolve().parents[2] / "conf")


def to_dict(node: DictConfig) -> dict[str, Any]:
    """A config node as a resolved plain dict."""
    return cast(dict[str, Any], OmegaConf.to_container(node, resolve=True))


def collect_all(cfg: DictConfig) -> list[Path]:
    """Collects the main dataset and its generalization sets described by ``cfg``."""
    data = to_dict(cfg.data)
    generalization = data.pop("generalization", None) or {}
    jobs: list[tuple[dict[str, Any], dict[str, Any]]] = [(data, {})]
    for offset, (name, extra) in enumerate(generalization.items(), start=1):
        extra = dict(extra)
        env_overrides = extra.pop("env", None) or {}
        jobs.append(({**data, "seed": data["seed"] + offset, **extra, "name": name}, env_overrides))
    paths = []
    for job, env_overrides in jobs:
        env_fn = instantiate(cfg.env, **env_overrides, _partial_=True, _convert_="all")
        env_config = to_dict(cfg.env)
        env_config.pop("_target_")
        env_config.update(env_overrides)
        paths.append(collect_dataset(env_fn=env_fn, env_config=env_config, **job))
    return paths


@hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="config")
def main(cfg: DictConfig) -> None:
    """Entry point: collect every dataset of the composed config."""
    for path in collect_all(cfg):
        logger.info("Dataset ready: %s", path)


if __name__ == "__main__":
    main()
