"""Ctrl-C and SIGTERM: workers started with SIGINT blocked, deferred stops, the entry points' exit."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from kinet_rl.interrupts import (
    Interrupted,
    deferred_interrupts,
    exit_on_interrupt,
    worker_processes,
)


@pytest.fixture(autouse=True)
def python_handlers():
    """Python's own SIGINT handler (a background shell starts pytest with SIGINT ignored), and
    checks that each test leaves the handlers as it found them."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    sigterm = signal.getsignal(signal.SIGTERM)
    yield
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    assert signal.getsignal(signal.SIGTERM) == sigterm
    signal.signal(signal.SIGINT, previous)


def blocked_signals(pid: int) -> set[int]:
    """The signals blocked in process ``pid`` (its ``SigBlk`` mask in /proc)."""
    status = Path(f"/proc/{pid}/status").read_text()
    mask = int(
        next(line for line in status.splitlines() if line.startswith("SigBlk:")).split()[1], 16
    )
    return {signum for signum in range(1, 65) if mask >> (signum - 1) & 1}


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc")
def test_workers_inherit_a_blocked_sigint_and_are_stopped() -> None:
    stopped = []

    def stop(process: subprocess.Popen) -> None:
        process.kill()
        process.wait()
        stopped.append(process.returncode)

    with worker_processes(lambda: subprocess.Popen(["sleep", "30"]), stop) as worker:
        assert signal.SIGINT in blocked_signals(worker.pid)
        assert signal.SIGTERM not in blocked_signals(worker.pid)  # terminate() still works
        assert signal.SIGINT not in blocked_signals(os.getpid())
    assert stopped == [-signal.SIGKILL]


def test_a_ctrl_c_during_the_start_arrives_after_it_and_the_workers_are_stopped() -> None:
    stopped = []

    def start() -> str:
        os.kill(os.getpid(), signal.SIGINT)  # held until start() returns
        return "workers"

    with pytest.raises(KeyboardInterrupt), worker_processes(start, stopped.append):
        pytest.fail("the interrupt must arrive before the block runs")
    assert stopped == ["workers"]


def test_a_deferred_signal_waits_for_the_safe_point() -> None:
    steps = []
    with pytest.raises(Interrupted) as caught, deferred_interrupts() as stop:
        for step in range(5):
            if step == 1:
                os.kill(os.getpid(), signal.SIGTERM)
            steps.append(step)  # the step during which the signal came still runs
            if stop.requested:
                break
    assert steps == [0, 1] and caught.value.signum == signal.SIGTERM


def test_a_second_signal_stops_at_once() -> None:
    steps = []
    with pytest.raises(Interrupted), deferred_interrupts():
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGINT)
        steps.append("after")
    assert steps == []


def test_a_disabled_deferral_lets_signals_act_as_usual() -> None:
    with pytest.raises(KeyboardInterrupt), deferred_interrupts(enabled=False):
        os.kill(os.getpid(), signal.SIGINT)
        pytest.fail("SIGINT must raise at once")


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_entry_point_prints_how_to_resume_and_exits_128_plus_the_signal(
    signum: int, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(sys, "argv", ["collect.py", "+exp=smoke", "data.root=my data"])
    cleaned = []

    @exit_on_interrupt("kinet_rl.collect")
    def main() -> None:
        try:
            os.kill(os.getpid(), signum)
        finally:
            cleaned.append(True)

    with pytest.raises(SystemExit) as caught:
        main()
    assert caught.value.code == 128 + signum and cleaned == [True]
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [
        f"Stopped by {signal.Signals(signum).name}; finished work is kept. To resume, run the "
        "same command again: python -m kinet_rl.collect +exp=smoke 'data.root=my data'"
    ]


def test_an_entry_point_that_finishes_returns_its_value() -> None:
    assert exit_on_interrupt("kinet_rl.plan")(lambda x: x + 1)(1) == 2
