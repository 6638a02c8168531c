"""Ctrl-C and SIGTERM: one clean stop for every long job, its worker processes and its command line.

* :func:`worker_processes` starts worker processes (collectors, episode pools) with SIGINT
  blocked, so the workers inherit the block: Ctrl-C, which the terminal sends to the whole
  process group, reaches only the parent, which stops the workers itself.
* :func:`deferred_interrupts` holds SIGINT and SIGTERM during work that must not stop halfway
  (a training step): the first signal is recorded and acted on at a safe point, a second one
  stops at once.
* :func:`exit_on_interrupt` wraps an entry point: SIGTERM takes the same path as Ctrl-C (an
  :class:`Interrupted` exception, so every ``finally`` runs), and an interrupted run ends with
  one line saying how to resume and the conventional exit status 128 + signal (130, 143).
"""

from __future__ import annotations

import functools
import logging
import shlex
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

logger = logging.getLogger(__name__)

T = TypeVar("T")
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupted(KeyboardInterrupt):
    """A stop requested by a signal; a ``KeyboardInterrupt``, so existing handlers treat it alike.

    Attributes:
        signum: The signal (``SIGINT`` or ``SIGTERM``).
    """

    def __init__(self, signum: int = signal.SIGINT) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _raise_interrupted(signum: int, frame: Any) -> None:
    raise Interrupted(signum)


@contextmanager
def worker_processes(start: Callable[[], T], stop: Callable[[T], None]) -> Iterator[T]:
    """Yields ``start()``, run with SIGINT blocked, and calls ``stop(workers)`` however the block ends.

    Processes started by ``start`` inherit the blocked SIGINT (the mask survives fork and exec),
    so they ignore Ctrl-C; a Ctrl-C that reaches this process meanwhile is delivered once
    ``start`` returns, and then ``stop`` still runs. ``stop`` must end the workers (terminate
    them if they do not finish promptly); SIGTERM still reaches them.
    """
    workers: T | None = None
    pending: list[int] = []
    # Another thread of this process (torch's, tqdm's) may take a process-directed SIGINT that the
    # mask holds back from this one; a handler that only records it covers that case.
    main = threading.current_thread() is threading.main_thread()
    previous = (
        signal.signal(signal.SIGINT, lambda signum, frame: pending.append(signum)) if main else None
    )
    try:
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            workers = start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
            if previous is not None:
                signal.signal(signal.SIGINT, previous)
        if pending:
            raise KeyboardInterrupt
        yield workers
    finally:
        if workers is not None:
            stop(workers)


class InterruptDeferral:
    """What :func:`deferred_interrupts` recorded: the signal that asked to stop, if any."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def _record(self, signum: int, frame: Any) -> None:
        if self.signum is not None:
            raise Interrupted(signum)
        self.signum = signum
        logger.warning(
            "%s received: stopping at the next safe point (send it again to stop at once).",
            signal.Signals(signum).name,
        )

    @property
    def requested(self) -> bool:
        """Whether a stop signal arrived."""
        return self.signum is not None

    def raise_if_requested(self) -> None:
        """Raises :class:`Interrupted` if a stop signal arrived."""
        if self.signum is not None:
            raise Interrupted(self.signum)


@contextmanager
def deferred_interrupts(enabled: bool = True) -> Iterator[InterruptDeferral]:
    """Within the block, SIGINT and SIGTERM only record a stop request (a second one raises).

    The caller checks ``deferral.requested`` at safe points; a request still pending when the
    block ends raises :class:`Interrupted` there. Outside the main thread (where Python cannot
    set signal handlers), or with ``enabled=False``, signals act as usual.
    """
    deferral = InterruptDeferral()
    if not enabled or threading.current_thread() is not threading.main_thread():
        yield deferral
        return
    previous = {signum: signal.signal(signum, deferral._record) for signum in STOP_SIGNALS}
    try:
        yield deferral
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    deferral.raise_if_requested()


def exit_on_interrupt(module: str) -> Callable[[Callable[..., T]], Callable[..., T]]:
    """Decorates the ``main`` of ``python -m <module>``: a clean stop on Ctrl-C or SIGTERM.

    SIGTERM raises :class:`Interrupted` like Ctrl-C does, so worker processes are stopped and
    completed work is kept by the ``finally`` blocks of the job. The process then prints one line
    with the command that resumes the job (the same command) and exits with 128 + the signal.
    """

    def decorate(main: Callable[..., T]) -> Callable[..., T]:
        @functools.wraps(main)
        def wrapped(*args: Any, **kwargs: Any) -> T:
            previous = signal.signal(signal.SIGTERM, _raise_interrupted)
            try:
                return main(*args, **kwargs)
            except KeyboardInterrupt as err:
                signum = err.signum if isinstance(err, Interrupted) else signal.SIGINT
            finally:
                signal.signal(signal.SIGTERM, previous)
            command = shlex.join(["python", "-m", module, *sys.argv[1:]])
            sys.stderr.write(
                f"\nStopped by {signal.Signals(signum).name}; finished work is kept. "
                f"To resume, run the same command again: {command}\n"
            )
            raise SystemExit(128 + signum)

        return wrapped

    return decorate
