"""``trainer.compile``: the KINet loss traces into one graph, and the compiled training step gives
the eager step's losses and gradients (slow: dynamo tracing takes seconds)."""

from __future__ import annotations

import functools
from collections.abc import Callable

import pytest
import torch
from tensordict import TensorDict

from kinet_rl.models import KINetLoss, KINetWorldModel
from kinet_rl.training.loop import Trainer

pytestmark = pytest.mark.slow


def test_the_kinet_loss_traces_into_one_graph(
    tiny_kinet: Callable[..., KINetWorldModel], transition_batch: Callable[..., TensorDict]
) -> None:
    loss = KINetLoss(tiny_kinet().train(), rollout_weight=1.0)
    explanation = torch._dynamo.explain(loss)(transition_batch())
    assert explanation.graph_break_count == 0, explanation.break_reasons


def test_the_compiled_step_gives_the_eager_step(
    kinet_trainer: Callable[..., Trainer], monkeypatch: pytest.MonkeyPatch
) -> None:
    # aot_eager: dynamo's graph and its autograd, run by eager kernels; inductor would draw the
    # edge-sampling noise from its own generator, so the two steps would not see the same noise
    monkeypatch.setattr(torch, "compile", functools.partial(torch.compile, backend="aot_eager"))
    steps = {}
    for compiled in (False, True):
        trainer = kinet_trainer(f"compiled={compiled}", compile=compiled)
        torch.manual_seed(1)
        losses = trainer.train_step()
        assert (trainer.compiled_loss is not None) == compiled  # compiling did not fail
        steps[compiled] = losses, [p.grad for p in trainer.loss_module.parameters()]
    (eager, eager_grads), (compiled, compiled_grads) = steps[False], steps[True]
    for name, value in eager.items():
        torch.testing.assert_close(compiled[name], value, msg=name)
    for a, b in zip(compiled_grads, eager_grads, strict=True):
        torch.testing.assert_close(a, b)
