"""Train KINet: ``python -m kinet_rl.train [+exp=<name>] [overrides]``.

Collects the experiment's dataset if it is missing (resuming a partial one), trains the world
model with periodic validation, checkpoints and image summaries in the run directory
(``runs/<exp_name>``; re-running the same command resumes), then evaluates keypoint accuracy and
forward prediction on held-out episodes and writes ``report.md``
(:func:`kinet_rl.pipeline.run_experiment`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, cast

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from kinet_rl.configs import config_dir
from kinet_rl.interrupts import exit_on_interrupt
from kinet_rl.pipeline import check_config, run_experiment


def run(cfg: DictConfig, run_dir: Path) -> dict[str, Any]:
    """Checks a composed config (before any work), then runs its experiment in ``run_dir``;
    returns its results."""
    container = cast(dict[str, Any], OmegaConf.to_container(cfg, resolve=True))
    return run_experiment(
        check_config(container),
        lambda: instantiate(cfg.model, _convert_="all"),
        lambda model: instantiate(cfg.loss, world_model=model, _convert_="all"),
        run_dir,
    )


@exit_on_interrupt("kinet_rl.train")
@hydra.main(version_base="1.3", config_path=config_dir(), config_name="config")
def main(cfg: DictConfig) -> None:
    """Entry point."""
    run_dir = Path(HydraConfig.get().runtime.output_dir)
    results = run(cfg, run_dir)
    if results:
        print(f"\nRun directory: {run_dir}")
        print((run_dir / "report.md").read_text())
        rearrangement = run_dir / "rearrangement" / "rearrangement.md"
        if "rearrangement" in results and rearrangement.exists():
            print(rearrangement.read_text())


if __name__ == "__main__":
    main()
