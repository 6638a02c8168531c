"""The training loop: resumable, NaN-guarded, logged, with periodic validation and images."""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import torch
from tensordict import TensorDictBase
from torch import nn
from torchrl.record.loggers import Logger
from tqdm.auto import tqdm

from kinet_rl.config_schema import at_least, require
from kinet_rl.interrupts import deferred_interrupts
from kinet_rl.training.checkpoint import TrainingCheckpoint
from kinet_rl.training.distributed import DistContext, mean_across_processes, wrap_data_parallel

log = logging.getLogger(__name__)


class TransitionSampler(Protocol):
    """Anything that draws random batches of transitions (e.g. a kinet_rl dataset split)."""

    def sample(
        self,
        batch_size: int,
        generator: torch.Generator | None = None,
        steps_per_episode: int = 1,
        horizon: int = 1,
    ) -> TensorDictBase:
        """A ``[batch_size]`` TensorDict of transitions (``steps_per_episode`` per episode, each
        with the ``horizon - 1`` pushes that follow); samplers may omit the two options."""
        ...


#: Values of ``TrainerSettings.precision``.
PRECISIONS = ("float32", "bfloat16")


class DivergenceError(RuntimeError):
    """The loss became NaN or infinite; the last good checkpoint is kept."""


@dataclass(frozen=True)
class TrainerSettings:
    """How long and how a model is trained.

    Args:
        steps: optimiser steps in total (a resumed run continues up to this count).
        batch_size: transitions per step and process.
        lr: Adam learning rate.
        grad_clip: gradient-norm clipping (0 disables it).
        log_every: steps between scalar logs.
        eval_every: steps between validations (and best-checkpoint updates).
        checkpoint_every: steps between checkpoints.
        val_batches: batches averaged per validation.
        seed: seed of batch sampling (each process adds its rank).
        steps_per_episode: transitions drawn from each sampled episode (> 1 gives a contrastive
            loss negatives from the same episode).
        horizon: pushes each training transition carries (> 1 for a multi-step rollout loss).
        precision: ``"float32"`` or ``"bfloat16"``: the training forward under bfloat16 autocast
            (mixed precision: convolutions and matmuls in bfloat16, weights, optimiser and
            validation in float32). Faster on CPUs with bfloat16 units (AVX512-BF16, AMX) and on
            recent GPUs; slower where bfloat16 is emulated.
        compile: train with the loss module compiled by ``torch.compile`` (its first steps take
            minutes to compile); a compile failure logs a warning and training goes on eagerly.
    """

    steps: int = 2000
    batch_size: int = 32
    lr: float = 1e-3
    grad_clip: float = 10.0
    log_every: int = 25
    eval_every: int = 250
    checkpoint_every: int = 250
    val_batches: int = 8
    seed: int = 0
    steps_per_episode: int = 1
    horizon: int = 1
    precision: str = "float32"
    compile: bool = False

    def __post_init__(self) -> None:
        at_least(self, 0, "steps", "grad_clip", "seed")
        at_least(self, 1, "batch_size", "log_every", "eval_every", "checkpoint_every")
        at_least(self, 1, "val_batches", "steps_per_episode", "horizon")
        require(self.lr > 0, "lr", self.lr, "a number > 0")
        require(
            self.batch_size % self.steps_per_episode == 0,
            "steps_per_episode",
            self.steps_per_episode,
            f"a divisor of batch_size={self.batch_size}",
        )
        require(self.precision in PRECISIONS, "precision", self.precision, f"one of {PRECISIONS}")


Validator = Callable[[int], dict[str, float]]
LossFunction = Callable[[TensorDictBase], TensorDictBase]


def total_loss(losses: TensorDictBase) -> torch.Tensor:
    """Sum of every ``loss_*`` entry of a loss module's output."""
    return sum(v for k, v in losses.items() if str(k).startswith("loss_"))  # type: ignore[return-value]


def _check_finite(losses: TensorDictBase, step: int) -> None:
    bad = [k for k, v in losses.items() if not torch.isfinite(v).all()]
    if bad:
        raise DivergenceError(
            f"Loss terms {bad} are not finite at step {step}; training stopped and the last good "
            "checkpoint was kept. Lower trainer.lr, raise trainer.grad_clip, or check the data."
        )


class Trainer:
    """Trains a loss module's parameters on sampled transitions, resuming from its run directory.

    Args:
        loss_module: a module mapping a batch TensorDict to ``loss_*`` scalars (e.g. ``KINetLoss``).
        train_data: sampler of training batches.
        val_data: sampler of validation batches.
        settings: see :class:`TrainerSettings`.
        checkpoint: the run's :class:`TrainingCheckpoint` (run directory and identity).
        logger: a TorchRL logger.
        ctx: data-parallel context (single process by default).
        on_validate: optional extra validation (e.g. keypoint accuracy, image summaries) called
            with the step on the main process; its scalars are logged.
    """

    def __init__(
        self,
        loss_module: nn.Module,
        train_data: TransitionSampler,
        val_data: TransitionSampler,
        settings: TrainerSettings,
        checkpoint: TrainingCheckpoint,
        logger: Logger,
        ctx: DistContext | None = None,
        on_validate: Validator | None = None,
    ) -> None:
        self.ctx = ctx or DistContext()
        self.loss_module = loss_module.to(self.ctx.device)
        self.parallel_loss = wrap_data_parallel(self.loss_module, self.ctx)
        self.train_data, self.val_data = train_data, val_data
        self.settings = settings
        self.checkpoint = checkpoint
        self.logger = logger
        self.on_validate = on_validate
        # Not fused: fused Adam is ~1-3% faster on CPU but rounds differently, which changes
        # every trained model of docs/results.md for the same seed.
        self.optimizer = torch.optim.Adam(self.loss_module.parameters(), lr=settings.lr)
        self.compiled_loss: LossFunction | None = None
        if settings.compile:
            self.compiled_loss = torch.compile(self.parallel_loss)  # compiles at the first call
        self.generator = torch.Generator().manual_seed(settings.seed + self.ctx.rank)
        self.step = 0
        self.best_val = math.inf

    def state_dict(self) -> dict[str, Any]:
        return {
            "model": self.loss_module.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "step": self.step,
            "best_val": self.best_val,
            "generator": self.generator.get_state(),
            "logger": self.logger.state_dict(),
        }

    def resume(self) -> bool:
        """Loads the run's latest checkpoint if there is one; returns whether it did."""
        state = self.checkpoint.load_latest()
        if state is None:
            return False
        self.loss_module.load_state_dict(state["model"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.step, self.best_val = int(state["step"]), float(state["best_val"])
        self.generator.set_state(state["generator"])
        self.logger.load_state_dict(state["logger"])
        return True

    def _batch(self, data: TransitionSampler) -> TensorDictBase:
        s = self.settings
        options = {"steps_per_episode": s.steps_per_episode, "horizon": s.horizon}
        extra = {name: value for name, value in options.items() if value != 1}  # plain samplers
        return data.sample(s.batch_size, self.generator, **extra).to(self.ctx.device)

    def train_step(self) -> TensorDictBase:
        """One optimiser step; returns the detached loss terms."""
        self.loss_module.train()
        losses = self._losses_with_grad(self._batch(self.train_data))
        if self.settings.grad_clip > 0:
            nn.utils.clip_grad_norm_(
                self.loss_module.parameters(), self.settings.grad_clip, foreach=True
            )
        self.optimizer.step()
        self.step += 1
        return losses.detach()

    def _losses_with_grad(self, batch: TensorDictBase) -> TensorDictBase:
        """The loss terms of ``batch``, their gradients in the parameters: compiled if asked,
        eagerly once compiling has failed."""
        if self.compiled_loss is not None:
            try:
                return self._backward(self.compiled_loss, batch)
            except DivergenceError:
                raise
            except Exception as err:  # dynamo, inductor or the C++ toolchain, at any stage
                log.warning(
                    "torch.compile of the loss failed (%s: %s); training goes on eagerly.",
                    type(err).__name__,
                    err,
                )
                self.compiled_loss = None
        return self._backward(self.parallel_loss, batch)

    def _backward(self, loss_function: LossFunction, batch: TensorDictBase) -> TensorDictBase:
        """``loss_function``'s terms of ``batch`` (at the settings' precision), back-propagated."""
        with torch.autocast(
            self.ctx.device.type, torch.bfloat16, enabled=self.settings.precision == "bfloat16"
        ):
            losses = loss_function(batch)
        losses = losses.float()  # terms reduced in bfloat16 are summed and logged in float32
        _check_finite(losses, self.step)
        self.optimizer.zero_grad(set_to_none=True)
        total_loss(losses).backward()
        return losses

    @torch.no_grad()
    def validate(self) -> dict[str, float]:
        """Mean validation loss terms over ``val_batches`` batches (plus ``on_validate``)."""
        self.loss_module.eval()
        sums: dict[str, float] = {}
        for _ in range(self.settings.val_batches):
            for key, value in self.loss_module(self._batch(self.val_data)).items():
                sums[f"val/{key}"] = sums.get(f"val/{key}", 0.0) + value.item()
        scores = {
            k: mean_across_processes(v / self.settings.val_batches, self.ctx)
            for k, v in sums.items()
        }
        scores["val/loss"] = sum(v for k, v in scores.items() if k.startswith("val/loss_"))
        if self.on_validate is not None and self.ctx.is_main:
            scores.update(self.on_validate(self.step))
        return scores

    def _log(self, scalars: dict[str, float]) -> None:
        if self.ctx.is_main:
            for name, value in scalars.items():
                self.logger.log_scalar(name, value, step=self.step)

    def _save(self, best: bool = False) -> None:
        if self.ctx.is_main:
            self.checkpoint.save(self.state_dict(), best=best)

    def fit(self) -> dict[str, float]:
        """Trains until ``settings.steps``; returns the last validation scores.

        Ctrl-C or SIGTERM (in a single-process run) lets the current step, with its logging and
        validation, finish, saves the checkpoint and raises
        :class:`~kinet_rl.interrupts.Interrupted`; a second signal stops at once, keeping the
        last periodic checkpoint. Rerunning resumes from the checkpoint.
        """
        s = self.settings
        bar = tqdm(
            total=s.steps,
            initial=self.step,
            desc="train",
            disable=not self.ctx.is_main,
            dynamic_ncols=True,
        )
        scores: dict[str, float] = {}
        with bar, deferred_interrupts(enabled=self.ctx.world_size == 1) as stop:
            while self.step < s.steps:
                losses = self.train_step()
                bar.update(1)
                if self.step % s.log_every == 0 or self.step == s.steps:
                    terms = {f"train/{k}": v.item() for k, v in losses.items()}
                    terms["train/loss"] = sum(terms.values())
                    self._log(terms)
                    bar.set_postfix(loss=f"{terms['train/loss']:.4f}")
                if self.step % s.eval_every == 0 or self.step == s.steps:
                    scores = self.validate()
                    self._log(scores)
                    is_best = scores["val/loss"] < self.best_val
                    self.best_val = min(self.best_val, scores["val/loss"])
                    self._save(best=is_best)
                elif self.step % s.checkpoint_every == 0:
                    self._save()
                if stop.requested:
                    self._save()
                    log.warning(
                        "Stopped at step %d: saved %s", self.step, self.checkpoint.last_path
                    )
                    stop.raise_if_requested()
        if not scores:
            scores = self.validate()
        return scores
