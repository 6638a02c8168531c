"""Nox sessions: the README's commands and what CI runs.

`nox -s tests` is the test command CI runs; CI then runs `nox -s wheel`, the installed-package
check. Every session installs the package with the exact pins of ci/constraints.txt, so a fresh
machine reproduces CI.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import nox

nox.options.reuse_existing_virtualenvs = True
nox.options.sessions = ["tests"]

CONSTRAINTS = ("-c", "ci/constraints.txt")
#: Config files of a user's own (an experiment and a comparison-table scale), used from outside.
USER_CONF = Path(__file__).resolve().parent / "ci" / "user_conf"
#: Rearrangement evaluation in seconds: one short episode, a tiny planner.
TINY_EVAL = [
    "eval.episodes=1",
    "eval.num_steps=2",
    "eval.num_objects=[1]",
    "eval.geometries=[train]",
    "eval.backgrounds=[]",
    "eval.generalization_episodes=1",
    "eval.workers=1",
    "eval.videos=1",
    "eval.planner.num_candidates=8",
    "eval.planner.top_k=2",
    "eval.planner.optim_steps=1",
]
# Renders a current and a goal camera image of the smoke scene for `python -m kinet_rl.plan`.
RENDER_IMAGES = """
from PIL import Image
from kinet_rl.envs import make_env
pixels = make_env(image_size=32, seed=0).rollout(3)["pixels"].numpy()
Image.fromarray(pixels[0]).save("now.png")
Image.fromarray(pixels[-1]).save("goal.png")
"""
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


@nox.session(reuse_venv=False)
def wheel(session: nox.Session) -> None:
    """The package as a user installs it: builds the wheel, installs it (not editable) in a fresh
    virtual environment and runs every entry point at smoke scale from an empty folder, with
    config files of the user's own (ci/user_conf) added by --config-dir."""
    dist = Path(session.create_tmp()) / "dist"
    shutil.rmtree(dist, ignore_errors=True)
    session.run("python", "-m", "pip", "wheel", "--no-deps", "--wheel-dir", str(dist), ".")
    (wheel_file,) = dist.glob("kinet_rl-*.whl")
    session.install(*CONSTRAINTS, str(wheel_file))
    work = Path(tempfile.mkdtemp(prefix="kinet_rl_wheel_"))
    session.chdir(work)
    configs = session.run(
        "python", "-c", "from kinet_rl.configs import config_dir; print(config_dir())", silent=True
    )
    if "site-packages" not in str(configs):
        session.error(f"The installed kinet_rl reads its configs from {configs}, not the wheel.")
    user = ("--config-dir", str(USER_CONF))
    composed = session.run(
        "python", "-m", "kinet_rl.train", *user, "+exp=user_smoke", "--cfg", "job", silent=True
    )
    if "exp_name: user_smoke" not in str(composed):
        session.error(f"The user's experiment did not compose:\n{composed}")
    session.run("python", "-m", "kinet_rl.collect", "+exp=smoke", env=RENDER_ENV)
    session.run("python", "-m", "kinet_rl.train", "+exp=smoke", env=RENDER_ENV)
    session.run("python", "-m", "kinet_rl.evaluate", "+exp=smoke", *TINY_EVAL, env=RENDER_ENV)
    session.run("python", "-c", RENDER_IMAGES, env=RENDER_ENV)
    checkpoint = "runs/smoke/kinet.pt"
    session.run(
        "python", "-m", "kinet_rl.plan", "--checkpoint", checkpoint, "--image", "now.png",
        "--goal", "goal.png", "--candidates", "8", "--top-k", "2", "--iterations", "1",
    )  # fmt: skip
    session.run("python", "-m", "kinet_rl.tables", *user, "tables=wheel", env=RENDER_ENV)
    expected = [
        "data/smoke/metadata.json",
        "runs/smoke/report.md",
        checkpoint,
        "runs/smoke/rearrangement/rearrangement.md",
        "runs/tables_wheel/tables.md",
    ]
    missing = [name for name in expected if not (work / name).is_file()]
    if missing:
        session.error(f"Not written in the working directory {work}: {missing}")
    shutil.rmtree(work)


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
