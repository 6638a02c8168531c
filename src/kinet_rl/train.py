"""Train KINet: ``python -m kinet_rl.train [+exp=<name>] [overrides]``.

Collects the experiment's dataset if it is missing (resuming a partial one), trains the world
model with periodic validation, checkpoints and image summaries in the run directory
(``runs/<exp_name>``; re-running the same command resumes), then evaluates keypoint accuracy and
forward prediction on held-out episodes and writes ``report.md``.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, cast

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from kinet_rl.atomic import atomic_write_json
from kinet_rl.collect import collect_all
from kinet_rl.control.evaluation import evaluate_rearrangement
from kinet_rl.data import load_dataset
from kinet_rl.evaluation.report import TrainingReport
from kinet_rl.models import KINetWorldModel
from kinet_rl.training.checkpoint import TrainingCheckpoint
from kinet_rl.training.distributed import init_distributed
from kinet_rl.training.loggers import make_logger
from kinet_rl.training.loop import Trainer, TrainerSettings

log = logging.getLogger(__name__)

CONF_DIR = str(Path(__file__).resolve().parents[2] / "conf")


def dataset_path(cfg: DictConfig) -> Path:
    """Folder of the experiment's main dataset."""
    return Path(cfg.data.root) / cfg.data.name


def run_identity(cfg: DictConfig) -> dict:
    """The settings a checkpoint must share with the run that resumes it."""
    return {
        "model": OmegaConf.to_container(cfg.model, resolve=True),
        "loss": OmegaConf.to_container(cfg.loss, resolve=True),
        "dataset": str(dataset_path(cfg)),
        "batch_size": cfg.trainer.batch_size,
    }


def short_rearrangement(cfg: DictConfig, model: KINetWorldModel, run_dir: Path) -> dict:
    """A few rearrangement episodes by GraphMPC against the other methods (kinet_rl.evaluate)."""
    settings = cast(dict[str, Any], OmegaConf.to_container(cfg, resolve=True))
    settings["eval"]["episodes"] = cfg.report.rearrangement_episodes
    summary = evaluate_rearrangement(model.cpu(), settings, run_dir / "rearrangement")["summary"]
    return {
        condition: {method: stats["final_distance"] for method, stats in by_method.items()}
        for condition, by_method in summary.items()
    }


def train(cfg: DictConfig, run_dir: Path) -> dict:
    """Runs the whole job described by ``cfg`` in ``run_dir``; returns the evaluation results."""
    ctx = init_distributed(cfg.device)
    torch.manual_seed(cfg.seed + ctx.rank)
    if ctx.is_main:
        collect_all(cfg)
    if ctx.world_size > 1:
        torch.distributed.barrier()
    expect = {k: cfg.env[k] for k in ("task", "camera", "image_size", "num_objects")}
    data = {
        split: load_dataset(dataset_path(cfg), split, expect) for split in ("train", "val", "test")
    }

    model = instantiate(cfg.model, _convert_="all")
    loss = instantiate(cfg.loss, world_model=model, _convert_="all")
    checkpoint = TrainingCheckpoint(run_dir, run_identity(cfg))
    logger = make_logger(cfg.logger.kind, run_dir, cfg.exp_name, None, cfg.logger.wandb_kwargs)
    report = TrainingReport.for_run(cfg, run_dir, model, data["val"], data["test"])
    trainer = Trainer(
        loss,
        data["train"],
        data["val"],
        TrainerSettings(**cast(dict[str, Any], OmegaConf.to_container(cfg.trainer, resolve=True))),
        checkpoint,
        logger,
        ctx,
        on_validate=report.on_validate,
    )
    if trainer.resume():
        log.info("Resumed %s at step %d", run_dir, trainer.step)
    trainer.fit()
    if not ctx.is_main:
        return {}
    name = "kinet.pt" if isinstance(model, KINetWorldModel) else "model.pt"
    model.save_checkpoint(run_dir / name, config=OmegaConf.to_container(cfg, resolve=True))
    results = {**report.final(trainer.step), "world_size": ctx.world_size}
    if isinstance(model, KINetWorldModel) and cfg.report.rearrangement_episodes > 0:
        results["rearrangement"] = short_rearrangement(cfg, model, run_dir)
    atomic_write_json(run_dir / "results.json", results)
    return results


@hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="config")
def main(cfg: DictConfig) -> None:
    """Entry point."""
    run_dir = Path(HydraConfig.get().runtime.output_dir)
    results = train(cfg, run_dir)
    if results:
        print(f"\nRun directory: {run_dir}")
        print((run_dir / "report.md").read_text())
        rearrangement = run_dir / "rearrangement" / "rearrangement.md"
        if "rearrangement" in results and rearrangement.exists():
            print(rearrangement.read_text())


if __name__ == "__main__":
    main()
