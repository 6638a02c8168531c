"""Trainer: resumption gives the uninterrupted run, NaN, Ctrl-C and a full disk keep the checkpoint;
bfloat16 precision stays close to float32; a failing torch.compile falls back to eager."""

from __future__ import annotations

import logging
import os
import signal
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import torch
from tensordict import TensorDict
from torch import nn

from kinet_rl.atomic import CheckpointError, DiskFullError
from kinet_rl.config_schema import ConfigError
from kinet_rl.interrupts import Interrupted
from kinet_rl.training import TrainingCheckpoint
from kinet_rl.training.loggers import make_logger
from kinet_rl.training.loop import DivergenceError, Trainer, TrainerSettings


class LinearData:
    """Noise-free y = 3x - 1 transitions."""

    def sample(self, batch_size: int, generator: torch.Generator | None = None) -> TensorDict:
        x = torch.rand(batch_size, 1, generator=generator)
        return TensorDict({"x": x, "y": 3 * x - 1}, batch_size=[batch_size])


class RegressionLoss(nn.Module):
    """A loss module in the trainer's contract; returns NaN from step ``nan_after`` on."""

    def __init__(self, nan_after: int | None = None) -> None:
        super().__init__()
        self.net = nn.Linear(1, 1)
        self.calls = 0
        self.nan_after = nan_after

    def forward(self, batch: TensorDict) -> TensorDict:
        self.calls += self.training
        loss = (self.net(batch["x"]) - batch["y"]).pow(2).mean()
        if self.nan_after is not None and self.calls > self.nan_after:
            loss = loss * float("nan")
        return TensorDict({"loss_mse": loss}, batch_size=[])


class SignallingData(LinearData):
    """Linear data whose ``at``-th batch comes with ``signals`` sent to this process."""

    def __init__(self, at: int, signals: list[int]) -> None:
        self.at, self.signals, self.calls = at, signals, 0

    def sample(self, batch_size: int, generator: torch.Generator | None = None) -> TensorDict:
        self.calls += 1
        if self.calls == self.at:
            for signum in self.signals:
                os.kill(os.getpid(), signum)
        return super().sample(batch_size, generator)


def make_trainer(
    run_dir: Path,
    steps: int,
    loss: nn.Module | None = None,
    seed: int = 0,
    train_data: LinearData | None = None,
    **settings: Any,
) -> Trainer:
    torch.manual_seed(seed)
    settings = TrainerSettings(
        steps=steps, batch_size=8, lr=0.05, log_every=2, eval_every=4, checkpoint_every=2,
        val_batches=2, **settings,
    )  # fmt: skip
    return Trainer(
        loss or RegressionLoss(),
        train_data or LinearData(),
        LinearData(),
        settings,
        TrainingCheckpoint(run_dir, {"exp": "linear"}),
        make_logger("csv", run_dir, "linear"),
    )


def test_training_lowers_the_loss(tmp_path: Path) -> None:
    trainer = make_trainer(tmp_path, steps=0)
    before = trainer.validate()["val/loss"]
    trainer = make_trainer(tmp_path / "run", steps=200)
    after = trainer.fit()["val/loss"]
    assert after < before / 20


def assert_resumes_to_the_uninterrupted_run(run_dir: Path, from_step: int) -> None:
    """Resuming ``run_dir`` (stopped at ``from_step``) to 8 steps equals 8 uninterrupted steps."""
    straight = make_trainer(run_dir.parent / "straight", steps=8)
    straight.fit()
    resumed = make_trainer(run_dir, steps=8, seed=123)  # other init: must be overwritten
    assert resumed.resume() and resumed.step == from_step
    resumed.fit()
    for a, b in zip(
        straight.loss_module.parameters(), resumed.loss_module.parameters(), strict=True
    ):
        torch.testing.assert_close(a, b)


def test_resumed_run_equals_uninterrupted_run(tmp_path: Path) -> None:
    make_trainer(tmp_path / "split", steps=4).fit()
    assert_resumes_to_the_uninterrupted_run(tmp_path / "split", from_step=4)


def last_step(run_dir: Path) -> int:
    state = TrainingCheckpoint(run_dir, {"exp": "linear"}).load_latest()
    assert state is not None
    return int(state["step"])


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_stop_signal_finishes_the_step_saves_it_and_resumes_exactly(
    tmp_path: Path, signum: int
) -> None:
    interrupted = make_trainer(tmp_path / "split", steps=8, train_data=SignallingData(3, [signum]))
    with pytest.raises(Interrupted) as caught:
        interrupted.fit()
    assert caught.value.signum == signum
    assert last_step(tmp_path / "split") == 3  # the periodic checkpoint was at step 2
    assert_resumes_to_the_uninterrupted_run(tmp_path / "split", from_step=3)


def test_a_second_signal_stops_at_once_and_keeps_the_last_checkpoint(tmp_path: Path) -> None:
    signals = [signal.SIGINT, signal.SIGINT]
    trainer = make_trainer(tmp_path, steps=8, train_data=SignallingData(3, signals))
    with pytest.raises(Interrupted):
        trainer.fit()
    assert trainer.step == 2 and last_step(tmp_path) == 2


def test_a_full_disk_keeps_the_last_checkpoint(
    tmp_path: Path, full_disk: Callable[[int], None]
) -> None:
    full_disk(1)  # the checkpoint of step 2 fits, the one of step 4 does not
    with pytest.raises(DiskFullError, match="checkpoints/last.pt: no space left"):
        make_trainer(tmp_path, steps=4).fit()
    assert last_step(tmp_path) == 2


def test_nan_loss_stops_and_keeps_last_good_checkpoint(tmp_path: Path) -> None:
    trainer = make_trainer(tmp_path, steps=20, loss=RegressionLoss(nan_after=5))
    with pytest.raises(DivergenceError, match="not finite at step 5"):
        trainer.fit()
    state = TrainingCheckpoint(tmp_path, {"exp": "linear"}).load_latest()
    assert state is not None and state["step"] == 4
    assert all(torch.isfinite(v).all() for v in state["model"].values())


def test_checkpoint_of_another_experiment_is_refused(tmp_path: Path) -> None:
    make_trainer(tmp_path, steps=2).fit()
    with pytest.raises(CheckpointError, match="different experiment"):
        TrainingCheckpoint(tmp_path, {"exp": "other"}).load_latest()


def test_truncated_checkpoint_is_refused(tmp_path: Path) -> None:
    make_trainer(tmp_path, steps=2).fit()
    last = TrainingCheckpoint(tmp_path, {}).last_path
    last.write_bytes(last.read_bytes()[:100])
    with pytest.raises(CheckpointError, match="corrupt or truncated"):
        make_trainer(tmp_path, steps=4).resume()


def test_an_unknown_precision_is_refused() -> None:
    with pytest.raises(ConfigError, match="precision: got 'float16', expected one of"):
        TrainerSettings(precision="float16")


def test_bfloat16_precision_gives_float32_losses_and_gradients_to_its_precision(
    kinet_trainer: Callable[..., Trainer],
) -> None:
    steps = {}
    for precision in ("float32", "bfloat16"):
        trainer = kinet_trainer(precision, precision=precision)
        torch.manual_seed(1)  # the same edge-sampling noise
        losses = trainer.train_step()
        grads = torch.cat([p.grad.flatten() for p in trainer.loss_module.parameters()])
        steps[precision] = losses, grads
    (exact, exact_grads), (mixed, mixed_grads) = steps["float32"], steps["bfloat16"]
    assert set(mixed.keys()) == set(exact.keys()) and "loss_rollout" in exact
    for name, value in mixed.items():
        assert value.dtype == torch.float32, name
        torch.testing.assert_close(value, exact[name], rtol=2e-2, atol=1e-6, msg=name)
    error = ((mixed_grads - exact_grads).norm() / exact_grads.norm()).item()
    assert 0 < error < 5e-2  # computed in bfloat16 (not bit-equal), yet the same gradient


def test_a_failing_compile_warns_and_trains_eagerly(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    def failing_backend(graph: torch.fx.GraphModule, example_inputs: Any) -> Callable:
        raise RuntimeError("no C++ compiler here")

    compile_for_real = torch.compile
    monkeypatch.setattr(
        torch, "compile", lambda model: compile_for_real(model, backend=failing_backend)
    )
    with caplog.at_level(logging.WARNING, logger="kinet_rl.training.loop"):
        compiled = make_trainer(tmp_path / "compiled", steps=8, compile=True)
        compiled.fit()
    assert "torch.compile of the loss failed" in caplog.text and "no C++ compiler" in caplog.text
    assert compiled.compiled_loss is None  # compiled once, not at every step
    eager = make_trainer(tmp_path / "eager", steps=8)
    eager.fit()
    for a, b in zip(compiled.loss_module.parameters(), eager.loss_module.parameters(), strict=True):
        torch.testing.assert_close(a, b)
