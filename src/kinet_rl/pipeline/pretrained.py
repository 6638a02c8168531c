"""The model-card check of a shipped model: its keypoint accuracy on freshly collected episodes
(:func:`pretrained_keypoint_accuracy`; :func:`fresh_keypoint_accuracy` measures it before
shipping)."""

from __future__ import annotations

import functools
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from kinet_rl.data import collect_dataset, load_dataset
from kinet_rl.envs import make_env
from kinet_rl.envs.geometry import SceneGeometry
from kinet_rl.envs.settings import SceneSettings
from kinet_rl.evaluation.forward import keypoint_accuracy
from kinet_rl.evaluation.report import hit_radius
from kinet_rl.models.pretrained import model_card
from kinet_rl.models.world_model import KINetWorldModel

#: The check protocol of the shipped models' cards: episodes, pushes each, seed, frames scored.
CHECK_PROTOCOL = {"episodes": 6, "pushes_per_episode": 20, "seed": 2026, "frames": 120}


def fresh_keypoint_accuracy(
    model: KINetWorldModel,
    scene: SceneSettings,
    check: Mapping[str, Any],
    work_dir: Path,
    name: str = "check",
) -> float:
    """Keypoint accuracy of ``model`` on random-push episodes of ``scene`` collected afresh into
    ``work_dir`` by the ``check`` protocol (:data:`CHECK_PROTOCOL`'s keys): that many episodes
    of that many pushes from that seed, ``frames`` of their frames scored with the training
    report's hit radius."""
    env_config = {**scene.as_dict(), "max_steps": check["pushes_per_episode"]}
    path = collect_dataset(
        functools.partial(make_env, **env_config),
        env_config,
        root=work_dir,
        name=name,
        num_episodes=check["episodes"],
        seed=check["seed"],
        num_workers=1,
        splits={"train": 1.0},
        progress=False,
    )
    geometry = SceneGeometry.of_scene(scene.task, scene.camera, scene.image_size)
    return keypoint_accuracy(
        model,
        load_dataset(path, "train"),
        geometry,
        hit_radius(scene.image_size),
        num_frames=check["frames"],
        seed=check["seed"],
    )


def pretrained_keypoint_accuracy(name: str, work_dir: Path) -> float:
    """Keypoint accuracy of shipped model ``name`` on episodes collected afresh into ``work_dir``
    by the ``check`` protocol of its model card (:func:`kinet_rl.models.model_card`), which
    measured the card's ``check.keypoint_accuracy`` this way."""
    card = model_card(name)
    scene = SceneSettings.from_mapping(card["scene"])
    model = KINetWorldModel.from_pretrained(name)
    return fresh_keypoint_accuracy(model, scene, card["check"], work_dir, f"check_{name}")
