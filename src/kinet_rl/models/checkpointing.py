"""Checkpointing for models rebuilt from a constructor config: atomic saves, safe loads.

A model that mixes in :class:`ConfigCheckpointMixin` keeps its constructor arguments in
``self.config`` and names its file format in ``checkpoint_format``; the mixin writes weights,
config, the scene the model was trained on (typed :class:`~kinet_rl.envs.SceneSettings`: image
size and workspace) and its planning defaults (:class:`~kinet_rl.planners.PlanningDefaults`, the
objective and budget chosen on validation episodes) atomically and rebuilds the model from them
(``weights_only=True``), refusing files of another model or with settings other than the caller
expects. A loaded model carries ``scene`` and ``planning``.
"""

from __future__ import annotations

import logging
import os
from typing import Any, ClassVar, TypeVar

from torch import nn

from kinet_rl.atomic import CheckpointError, atomic_torch_save, safe_torch_load
from kinet_rl.envs.settings import SceneSettings
from kinet_rl.planners.world_model import PlanningDefaults

log = logging.getLogger(__name__)

ModelT = TypeVar("ModelT", bound="ConfigCheckpointMixin")


class ConfigCheckpointMixin:
    """``save_checkpoint``/``from_checkpoint`` for an ``nn.Module`` built from ``self.config``.

    Subclasses set the class attribute ``checkpoint_format`` (e.g. ``"kinet_rl.X/1"``) and store
    their JSON-like constructor arguments in ``self.config``.
    """

    checkpoint_format: ClassVar[str]
    #: File name of the trained model in a run directory.
    model_file: ClassVar[str] = "model.pt"
    config: dict[str, Any]
    #: The planning objective and budget (class default; a checkpoint's own once loaded).
    planning: PlanningDefaults
    #: The scene it was trained on (None until saved or loaded with one).
    scene: SceneSettings | None = None

    def save_checkpoint(self, path: str | os.PathLike, scene: SceneSettings | None = None) -> None:
        """Atomically writes weights, the constructor config, the ``scene`` trained on (default:
        ``self.scene``) and the planning defaults."""
        assert isinstance(self, nn.Module)
        scene = self.scene if scene is None else scene
        state = {
            "format": self.checkpoint_format,
            "model_config": dict(self.config),
            "scene": None if scene is None else scene.as_dict(),
            "planning": self.planning.as_dict(),
            "state_dict": self.state_dict(),
        }
        atomic_torch_save(state, path)
        log.info("Saved %s checkpoint to %s", type(self).__name__, path)

    @classmethod
    def from_checkpoint(
        cls: type[ModelT], path: str | os.PathLike, expected_config: dict[str, Any] | None = None
    ) -> ModelT:
        """Rebuilds a model saved by :meth:`save_checkpoint` (loaded with ``weights_only=True``).

        Args:
            path: Checkpoint file.
            expected_config: Constructor settings the caller relies on; any that differ from the
                stored ones raise :class:`CheckpointError`.

        Raises:
            CheckpointError: Missing, corrupt, truncated, foreign or mismatching checkpoint.
        """
        state = safe_torch_load(
            path, ("format", "model_config", "state_dict"), f"{cls.__name__}.save_checkpoint"
        )
        if state["format"] != cls.checkpoint_format:
            raise CheckpointError(
                f"Checkpoint {path} has format {state['format']!r}, but {cls.__name__} reads "
                f"{cls.checkpoint_format!r}; load it with the model class that wrote it."
            )
        stored = state["model_config"]
        diffs = {
            key: (value, stored.get(key, "<missing>"))
            for key, value in (expected_config or {}).items()
            if stored.get(key, "<missing>") != value
        }
        if diffs:
            detail = ", ".join(
                f"{k}: expected {e!r}, checkpoint {s!r}" for k, (e, s) in diffs.items()
            )
            raise CheckpointError(
                f"Checkpoint {path} does not match the requested model config ({detail}); "
                "use a checkpoint trained with these settings or change the config to match."
            )
        try:
            model = cls(**stored)
            assert isinstance(model, nn.Module)
            model.load_state_dict(state["state_dict"])
            planning = state.get("planning")
            if planning is not None:
                model.planning = PlanningDefaults.from_mapping(planning)
        except (TypeError, RuntimeError, KeyError, ValueError) as err:
            raise CheckpointError(
                f"Checkpoint {path} holds weights that do not fit its model config ({err}); "
                "the file was edited or written by an incompatible version, re-save it."
            ) from err
        scene = state.get("scene")
        model.scene = None if scene is None else SceneSettings.from_mapping(scene)
        return model


def checkpoint_scene(path: str | os.PathLike) -> SceneSettings | None:
    """The scene a checkpoint's model was trained on (None when the file does not say)."""
    state = safe_torch_load(path, ("format",), "save_checkpoint")
    scene = state.get("scene")
    return None if scene is None else SceneSettings.from_mapping(scene)
