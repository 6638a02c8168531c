"""Rearrangement evaluation of a trained model: ``python -m kinet_rl.evaluate +exp=<name> checkpoint=<path>``.

Runs KINet-GraphMPC (the paper's ``S`` and the embedding distance), MPC on keypoint positions
only, random pushes and the oracle MPC on the experiment's scene, the generalization table (1-5
objects x train/gen geometry) and extra backgrounds, with settings from the ``eval`` group
(``conf/eval/rearrange.yaml``). Writes plots, GIFs, ``rearrangement.md`` and
``rearrangement.json`` to ``<run dir>/rearrangement``, the plots and GIFs also to the TorchRL
logger of the ``logger`` group. The model is of the experiment's ``model`` group: a baseline's
experiment names its methods (e.g. ``+exp=blocks_topview_vcdn`` plans with ``model_mpc``).
Without ``checkpoint`` it uses the training run of the same experiment (``<run dir>/kinet.pt``,
``model.pt`` for a baseline); ``checkpoint=<model folder>`` loads a ``save_pretrained`` folder
and ``checkpoint=pretrained:<name>`` a KINet shipped with the package.

The paper's protocol (1,000 test episodes, T = 40, 3 blocks, top camera) with the shipped model:
``python -m kinet_rl.evaluate +exp=blocks_topview checkpoint=pretrained:blocks_topview
eval.episodes=1000 eval.num_objects=[] eval.backgrounds=[]``.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, cast

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.utils import get_class
from omegaconf import DictConfig, OmegaConf

from kinet_rl.configs import config_dir
from kinet_rl.interrupts import exit_on_interrupt
from kinet_rl.models.checkpointing import ConfigCheckpointMixin
from kinet_rl.models.pretrained import resolve_checkpoint
from kinet_rl.pipeline import check_config, evaluate_rearrangement
from kinet_rl.rearrangement import RearrangementSettings
from kinet_rl.training.loggers import make_logger

logger = logging.getLogger(__name__)


def settings_from_config(cfg: DictConfig) -> RearrangementSettings:
    """The evaluation settings of a composed config (needs the ``eval`` and ``env`` groups),
    after checking the whole config (:func:`kinet_rl.pipeline.check_config`)."""
    if cfg.get("eval") is None:
        raise ValueError(
            "The config has no 'eval' group; add `- eval: rearrange` to conf/config.yaml's "
            "defaults or pass +eval=rearrange."
        )
    container = cast(dict[str, Any], OmegaConf.to_container(cfg, resolve=True))
    return check_config(container).rearrangement


def evaluate(cfg: DictConfig, run_dir: Path) -> dict[str, Any]:
    """Loads the checkpoint and runs the full evaluation; returns its summary."""
    settings = settings_from_config(cfg)
    model_class = cast(type[ConfigCheckpointMixin], get_class(cfg.model._target_))
    default = run_dir / model_class.model_file
    checkpoint = resolve_checkpoint(cfg.get("checkpoint") or default)
    if not checkpoint.exists():
        raise FileNotFoundError(
            f"No checkpoint at {checkpoint}; train first (python -m kinet_rl.train +exp=...) or "
            f"pass checkpoint=<path to {default.name}> (or pretrained:<name>)."
        )
    model: Any = model_class.from_checkpoint(checkpoint)
    logger.info("Evaluating %s on %s", checkpoint, settings.scene)
    logs = cast(dict[str, Any], OmegaConf.to_container(cfg.logger, resolve=True))
    run_logger = make_logger(logs["kind"], run_dir, cfg.exp_name, None, logs.get("wandb_kwargs"))
    try:
        return evaluate_rearrangement(
            model,
            settings,
            run_dir / "rearrangement",
            generalization=True,
            progress=True,
            logger=run_logger,
        )
    finally:
        run_logger.close()


@exit_on_interrupt("kinet_rl.evaluate")
@hydra.main(version_base="1.3", config_path=config_dir(), config_name="config")
def main(cfg: DictConfig) -> None:
    """Entry point."""
    run_dir = Path(HydraConfig.get().runtime.output_dir)
    evaluate(cfg, run_dir)
    print((run_dir / "rearrangement" / "rearrangement.md").read_text())


if __name__ == "__main__":
    main()
