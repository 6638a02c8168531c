"""torchrl's own CEMPlanner and MPPIPlanner plan pushes over the WorldModelEnv of trained models.

A learned model that plans from camera images (the shipped KINet, ``blocks_topview``: goal
images) and a baseline trained here (IN, 3,000 steps on 40 simulated episodes: goal object
positions) each drive rearrangement episodes of the simulator through
``kinet_rl.planners.PushWorldModelEnv`` (a ``torchrl.envs.model_based.WorldModelEnv``) with
``torchrl.modules.CEMPlanner`` and ``MPPIPlanner``, and end closer to the goal than random
pushes on the same episodes (validation seeds, fixed). Measured numbers are in the test ids'
comments below.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.modules import CEMPlanner, MPPIPlanner
from torchrl.objectives.value import TDLambdaEstimator

from kinet_rl.baselines import ObjectInteractionModel
from kinet_rl.envs import SceneSettings
from kinet_rl.keys import GOAL_OBJECT_POS, GOAL_PIXELS, PIXELS
from kinet_rl.models import KINetWorldModel
from kinet_rl.planners import PushWorldModelEnv
from kinet_rl.rearrangement.controllers import RandomController, stacked
from kinet_rl.rearrangement.episodes import make_episode, run_episodes
from kinet_rl.rearrangement.settings import SPLIT_SEEDS, TaskSettings

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
EPISODES = 4
TASK = TaskSettings(num_steps=10)
BUDGET = {"planning_horizon": 1, "optim_steps": 3, "num_candidates": 64, "top_k": 8}


class _ZeroValue(nn.Module):
    """A value of 0 for every state: MPPI's advantage is then the imagined return."""

    def forward(self, state: torch.Tensor) -> torch.Tensor:
        return state.new_zeros(*state.shape[:-2], 1)


def torchrl_planner(kind: str, env: PushWorldModelEnv):
    if kind == "cem":
        return CEMPlanner(env, **BUDGET)
    value = TensorDictModule(_ZeroValue(), in_keys=[env.latent_key], out_keys=["state_value"])
    advantage = TDLambdaEstimator(gamma=1.0, lmbda=1.0, value_network=value)
    return MPPIPlanner(env, advantage, temperature=20.0, **BUDGET)


class TorchRLController:
    """A model's world model, its WorldModelEnv and a torchrl planner: the observation entries
    the model declares and the episodes' goals in, pushes out."""

    def __init__(self, model, kind: str) -> None:
        self.model = model
        self.world_model = model.world_model()
        self.planner = torchrl_planner(kind, PushWorldModelEnv(self.world_model))
        self.goal: TensorDict | None = None

    def reset(self, episodes) -> None:
        goals = {
            GOAL_PIXELS: lambda: torch.from_numpy(np.stack([e.goal_pixels for e in episodes])),
            GOAL_OBJECT_POS: lambda: torch.as_tensor(np.stack([e.goal_pos for e in episodes])),
        }
        keys = self.model.capabilities.goal
        self.goal = TensorDict({k: goals[k]() for k in keys}, batch_size=[len(episodes)])

    def act(self, observations) -> np.ndarray:
        observation = self.goal.clone(False)
        for key in self.model.capabilities.observes:
            dtype = None if key == PIXELS else torch.float32
            observation.set(key, stacked(observations, key, dtype))
        with torch.no_grad():
            state = self.world_model.observe(observation)
            return self.planner(state)["action"].numpy()


def final_distances_mm(controller, scene: SceneSettings, observes) -> np.ndarray:
    seeds = [SPLIT_SEEDS["validation"] + i for i in range(EPISODES)]
    episodes = [make_episode(scene, TASK, seed) for seed in seeds]
    try:
        results = run_episodes(episodes, controller, "planner", TASK, observes=observes)
    finally:
        for episode in episodes:
            episode.close()
    return np.array([1e3 * r.distances[-1] for r in results])


def random_pushes_mm(scene: SceneSettings) -> np.ndarray:
    seeds = tuple(SPLIT_SEEDS["validation"] + i for i in range(EPISODES))
    return final_distances_mm(RandomController(seeds), scene, ())


@pytest.fixture(scope="module")
def trained_in(tmp_path_factory) -> ObjectInteractionModel:
    """IN trained here on 40 simulated episodes of 3 blocks (GT state; 3,000 steps)."""
    tmp = tmp_path_factory.mktemp("in")
    command = [
        sys.executable, "-m", "kinet_rl.train", "+exp=blocks_topview_in", f"data.root={tmp}",
        f"hydra.run.dir={tmp / 'run'}", "data.generalization=null", "data.num_episodes=40",
        "data.num_workers=2", "env.image_size=32", "env.max_steps=20", "trainer.steps=3000",
        "trainer.batch_size=32", "trainer.eval_every=3000", "trainer.checkpoint_every=3000",
        "trainer.log_every=100", "report.horizons=[1]", "report.num_sequences=32",
        "report.rearrangement_episodes=0", "estimate=false",
    ]  # fmt: skip
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    result = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stderr[-4000:]
    return ObjectInteractionModel.from_checkpoint(tmp / "run" / "model.pt").eval()


@pytest.mark.parametrize("kind", ["cem", "mppi"])
def test_torchrl_planners_over_the_shipped_kinet_beat_random_pushes_from_goal_images(kind):
    model = KINetWorldModel.from_pretrained("blocks_topview")
    scene = model.scene
    planned = final_distances_mm(TorchRLController(model, kind), scene, (PIXELS,))
    random = random_pushes_mm(scene)
    print(f"KINet + torchrl {kind}: {planned.round(1)} mm; random pushes {random.round(1)} mm")
    assert planned.mean() < random.mean() - 5.0, (planned, random)


@pytest.mark.parametrize("kind", ["cem", "mppi"])
def test_torchrl_planners_over_a_trained_baseline_beat_random_pushes(kind, trained_in):
    scene = SceneSettings(image_size=32)
    planned = final_distances_mm(
        TorchRLController(trained_in, kind), scene, trained_in.capabilities.observes
    )
    random = random_pushes_mm(scene)
    print(f"IN + torchrl {kind}: {planned.round(1)} mm; random pushes {random.round(1)} mm")
    assert planned.mean() < random.mean() - 5.0, (planned, random)
