"""Nox sessions: the README's commands and what CI runs.

`nox -s tests` is the test command CI runs. Every session installs the package with the exact
pins of ci/constraints.txt, so a fresh machine reproduces CI.
"""

from __future__ import annotations

import os

import nox

nox.options.reuse_existing_virtualenvs = True
nox.options.sessions = ["tests"]

CONSTRAINTS = ("-c", "ci/constraints.txt")
RENDER_ENV = {"MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
# Tests run single-threaded: seeded learning tests then give the same numbers on any machine, and
# parallel workers (collectors, torchrun) do not oversubscribe the cores.
TEST_ENV = {**RENDER_ENV, "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1")}


def _install(session: nox.Session, extras: str = "test") -> None:
    session.install(*CONSTRAINTS, "-e", f".[{extras}]")


@nox.session
def tests(session: nox.Session) -> None:
    """Unit and integration tests (the README's test command; what CI runs)."""
    _install(session)
    session.run("pytest", "tests", *session.posargs, env=TEST_ENV)


@nox.session
def tests_fast(session: nox.Session) -> None:
    """Unit tests only: CPU, no rendering, seconds."""
    _install(session)
    session.run("pytest", "tests/unit", *session.posargs, env=TEST_ENV)


@nox.session
def train(session: nox.Session) -> None:
    """The main job: the default experiment (`python -m kinet_rl.train`), Hydra overrides as posargs."""
    _install(session)
    session.run("python", "-m", "kinet_rl.train", *session.posargs, env=RENDER_ENV)


@nox.session
def lint(session: nox.Session) -> None:
    """ruff lint and format check."""
    session.install("ruff")
    session.run("ruff", "check", "src", "tests", "bench", "noxfile.py")
    session.run("ruff", "format", "--check", "src", "tests", "bench", "noxfile.py")


@nox.session
def typecheck(session: nox.Session) -> None:
    """mypy on src/."""
    _install(session, extras="dev")
    session.run("mypy")
