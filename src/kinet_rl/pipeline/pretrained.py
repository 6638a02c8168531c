"""The model-card check of a shipped model: its keypoint accuracy on freshly collected episodes
(:func:`pretrained_keypoint_accuracy`)."""

from __future__ import annotations

import functools
from pathlib import Path

from kinet_rl.data import collect_dataset, load_dataset
from kinet_rl.envs import make_env
from kinet_rl.envs.geometry import SceneGeometry
from kinet_rl.envs.settings import SceneSettings
from kinet_rl.evaluation.forward import keypoint_accuracy
from kinet_rl.evaluation.report import hit_radius
from kinet_rl.models.pretrained import model_card
from kinet_rl.models.world_model import KINetWorldModel


def pretrained_keypoint_accuracy(name: str, work_dir: Path) -> float:
    """Keypoint accuracy of shipped model ``name`` on episodes collected afresh into ``work_dir``.

    Follows the ``check`` protocol of its model card (:func:`kinet_rl.models.model_card`): that
    many random-push episodes of the card's scene and seed, every frame of them scored with the
    training report's hit radius. The card's ``check.keypoint_accuracy`` was measured this way.
    """
    card = model_card(name)
    check, scene = card["check"], SceneSettings.from_mapping(card["scene"])
    env_config = {**scene.as_dict(), "max_steps": check["pushes_per_episode"]}
    path = collect_dataset(
        functools.partial(make_env, **env_config),
        env_config,
        root=work_dir,
        name=f"check_{name}",
        num_episodes=check["episodes"],
        seed=check["seed"],
        num_workers=1,
        splits={"train": 1.0},
        progress=False,
    )
    geometry = SceneGeometry.of_scene(scene.task, scene.camera, scene.image_size)
    return keypoint_accuracy(
        KINetWorldModel.from_pretrained(name),
        load_dataset(path, "train"),
        geometry,
        hit_radius(scene.image_size),
        num_frames=check["frames"],
        seed=check["seed"],
    )
