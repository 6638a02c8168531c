"""Collect random-push datasets: ``python -m kinet_rl.collect [+exp=<name>] [overrides]``.

Collects ``data.name`` and then each ``data.generalization`` set under ``data.root``
(relative to the working directory; Hydra does not change it). Rerunning the same command
resumes interrupted datasets and skips complete ones (:func:`kinet_rl.pipeline.collect_datasets`).
"""

from __future__ import annotations

import logging
from typing import Any, cast

import hydra
from omegaconf import DictConfig, OmegaConf

from kinet_rl.configs import config_dir
from kinet_rl.interrupts import exit_on_interrupt
from kinet_rl.pipeline import check_config, collect_datasets

logger = logging.getLogger(__name__)


@exit_on_interrupt("kinet_rl.collect")
@hydra.main(version_base="1.3", config_path=config_dir(), config_name="config")
def main(cfg: DictConfig) -> None:
    """Entry point: check the composed config, then collect every dataset of it."""
    container = cast(dict[str, Any], OmegaConf.to_container(cfg, resolve=True))
    settings = check_config(container)
    for path in collect_datasets(settings.env, settings.data):
        logger.info("Dataset ready: %s", path)


if __name__ == "__main__":
    main()
