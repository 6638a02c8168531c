"""Train KINet: ``python -m kinet_rl.train [+exp=<name>] [overrides]``.

First logs the run's plan (:mod:`kinet_rl.estimate`): datasets, training, evaluation, device
and a wall-time estimate measured on this machine (``estimate=false`` skips measuring), naming
``+scale=cpu`` when that smaller scale is worth knowing. Then collects the experiment's dataset
if it is missing (resuming a partial one), trains the world
model with periodic validation, checkpoints and image summaries in the run directory
(``runs/<exp_name>``; re-running the same command resumes), then evaluates keypoint accuracy and
forward prediction on held-out episodes and writes ``report.md``
(:func:`kinet_rl.pipeline.run_experiment`).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, cast

import hydra
from hydra import compose
from hydra.core.hydra_config import HydraConfig
from hydra.errors import HydraException
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from kinet_rl.config_schema import ConfigError
from kinet_rl.configs import config_dir
from kinet_rl.estimate import SMALLER_SCALE, Experiment, describe_run
from kinet_rl.interrupts import exit_on_interrupt
from kinet_rl.pipeline import check_config, run_experiment
from kinet_rl.training.distributed import process_rank

log = logging.getLogger(__name__)


def experiment(cfg: DictConfig) -> Experiment:
    """A composed config, checked (before any work), with its model and loss factories."""
    container = cast(dict[str, Any], OmegaConf.to_container(cfg, resolve=True))
    return Experiment(
        check_config(container),
        lambda: instantiate(cfg.model, _convert_="all"),
        lambda model: instantiate(cfg.loss, world_model=model, _convert_="all"),
    )


def run(cfg: DictConfig, run_dir: Path, smaller: DictConfig | None = None) -> dict[str, Any]:
    """Checks a composed config, logs its plan (with ``smaller``, the config of a smaller
    scale to name), then runs its experiment in ``run_dir``; returns its results."""
    planned = experiment(cfg)
    if process_rank() == 0:  # the other torchrun processes wait for its collection anyway
        log.info(describe_run(planned, run_dir, smaller_experiment(smaller)))
    return run_experiment(planned.settings, planned.build_model, planned.build_loss, run_dir)


def smaller_experiment(smaller: DictConfig | None) -> Experiment | None:
    """The smaller scale's experiment, or None when there is none or its config is invalid
    (e.g. an override of the run that does not fit the smaller batch): it is only named."""
    if smaller is None:
        return None
    try:
        return experiment(smaller)
    except ConfigError as err:
        log.debug("Not naming %s: %s", SMALLER_SCALE, err)
        return None


def smaller_scale() -> DictConfig | None:
    """This command's config with ``+scale=cpu`` added, or None when it already sets a scale
    (or the overrides do not compose with it)."""
    hydra_cfg = HydraConfig.get()
    if hydra_cfg.runtime.choices.get("scale") is not None:
        return None
    overrides = [*hydra_cfg.overrides.task, SMALLER_SCALE]
    try:
        return compose(config_name="config", overrides=overrides)
    except HydraException as err:
        log.debug("Not naming %s: %s", SMALLER_SCALE, err)
        return None


@exit_on_interrupt("kinet_rl.train")
@hydra.main(version_base="1.3", config_path=config_dir(), config_name="config")
def main(cfg: DictConfig) -> None:
    """Entry point."""
    run_dir = Path(HydraConfig.get().runtime.output_dir)
    results = run(cfg, run_dir, smaller_scale())
    if results:
        print(f"\nRun directory: {run_dir}")
        print((run_dir / "report.md").read_text())
        rearrangement = run_dir / "rearrangement" / "rearrangement.md"
        if "rearrangement" in results and rearrangement.exists():
            print(rearrangement.read_text())


if __name__ == "__main__":
    main()
