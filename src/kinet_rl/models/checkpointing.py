"""Checkpointing for models rebuilt from a constructor config: atomic saves, safe loads.

A model that mixes in :class:`ConfigCheckpointMixin` keeps its constructor arguments in
``self.config`` and names its file format in ``checkpoint_format``; the mixin writes weights,
config, the scene the model was trained on (typed :class:`~kinet_rl.envs.SceneSettings`: image
size and workspace) and its planning defaults (:class:`~kinet_rl.planners.PlanningDefaults`, the
objective and budget chosen on validation episodes) atomically and rebuilds the model from them,
refusing files of another model or with settings other than the caller expects. Two layouts
hold the same: a ``.pt`` file (``save_checkpoint``, loaded with ``weights_only=True``; what a
run writes) and a model folder in the Hugging Face layout (``save_pretrained``: safetensors
weights, ``config.json`` and a model card, :mod:`kinet_rl.models.hub`), which
``from_pretrained`` loads from a folder, a shipped model's name or a Hub repo id, and
``push_to_hub`` uploads. A loaded model carries ``scene`` and ``planning``.
"""

from __future__ import annotations

import logging
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar, TypeVar

import torch
from torch import Tensor, nn

from kinet_rl.atomic import CheckpointError, atomic_torch_save, safe_torch_load
from kinet_rl.config_schema import ConfigError
from kinet_rl.envs.settings import SceneSettings
from kinet_rl.models.hub import (
    ModelCardError,
    ModelSceneError,
    card_text,
    plain,
    read_model_config,
    read_model_weights,
    upload_folder,
    write_model_folder,
)
from kinet_rl.models.pretrained import model_folder
from kinet_rl.planners.world_model import PlanningDefaults

log = logging.getLogger(__name__)

ModelT = TypeVar("ModelT", bound="ConfigCheckpointMixin")


class ConfigCheckpointMixin:
    """Saving and loading for an ``nn.Module`` built from ``self.config``: ``.pt`` checkpoints
    (``save_checkpoint``/``from_checkpoint``) and model folders (``save_pretrained``/
    ``from_pretrained``/``push_to_hub``).

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

    def _stored(self, scene: SceneSettings | None) -> dict[str, Any]:
        """What a checkpoint stores beside the weights (``config.json`` of a model folder)."""
        return {
            "format": self.checkpoint_format,
            "model_config": dict(self.config),
            "scene": None if scene is None else scene.as_dict(),
            "planning": self.planning.as_dict(),
        }

    def save_checkpoint(self, path: str | os.PathLike, scene: SceneSettings | None = None) -> None:
        """Atomically writes weights, the constructor config, the ``scene`` trained on (default:
        ``self.scene``) and the planning defaults."""
        assert isinstance(self, nn.Module)
        scene = self.scene if scene is None else scene
        atomic_torch_save({**self._stored(scene), "state_dict": self.state_dict()}, path)
        log.info("Saved %s checkpoint to %s", type(self).__name__, path)

    def save_pretrained(
        self,
        folder: str | os.PathLike,
        scene: SceneSettings | None = None,
        card: Mapping[str, Any] | None = None,
        license_id: str = "mit",
    ) -> Path:
        """Writes a model folder (Hugging Face layout): ``model.safetensors``, ``config.json``
        and ``README.md``, atomically; checks everything first.

        Args:
            folder: A new or empty folder.
            scene: The scene trained on (default: ``self.scene``, else the card's ``scene``).
            card: The model card's facts (``command``, ``data``, ``seed``, ``training`` with
                ``hardware`` and ``wall_time_s``, ``metrics``, ``intended_use``, ``limits``...);
                its ``model``, ``scene`` and ``planning`` are filled in from the model.
            license_id: The card's license (a Hub license id).

        Raises:
            ModelFolderExistsError: ``folder`` holds files; nothing is written.
            CheckpointError: ``self.config`` does not build a model that these weights fit.
            ModelSceneError: The card names a scene that cannot be built.
            ModelCardError: The card contradicts the model (class, scene or planning) or holds
                non-JSON data.
        """
        assert isinstance(self, nn.Module)
        state_dict = self.state_dict()
        self._check_weights_fit(plain(dict(self.config), "model config"), state_dict)
        scene, facts = self._card_facts(card, self.scene if scene is None else scene)
        stored = plain(self._stored(scene), "model config")
        path = write_model_folder(folder, stored, state_dict, card_text(facts, license_id))
        log.info("Saved %s model folder to %s", type(self).__name__, path)
        return path

    def push_to_hub(
        self,
        repo_id: str,
        *,
        scene: SceneSettings | None = None,
        card: Mapping[str, Any] | None = None,
        license_id: str = "mit",
        private: bool | None = None,
        token: str | None = None,
        commit_message: str = "Upload kinet_rl model",
    ) -> Any:
        """Saves the model folder (:meth:`save_pretrained`) into a temporary folder and uploads
        it to Hugging Face Hub repo ``repo_id`` (created if needed); needs ``kinet_rl[hub]``.
        Returns the Hub's commit info."""
        with tempfile.TemporaryDirectory(prefix="kinet_rl_push_") as tmp:
            folder = self.save_pretrained(Path(tmp) / "model", scene, card, license_id)
            return upload_folder(
                folder, repo_id, private=private, token=token, commit_message=commit_message
            )

    def _check_weights_fit(self, config: dict[str, Any], state_dict: Mapping[str, Tensor]) -> None:
        """Raises ``CheckpointError`` unless ``config`` builds a model that ``state_dict`` fits."""
        with torch.random.fork_rng(devices=[]):  # building draws initial weights
            try:
                twin = type(self)(**config)
            except (TypeError, ValueError, ConfigError) as err:
                raise CheckpointError(
                    f"{type(self).__name__}'s config {config} does not build the model ({err}); "
                    "its config was edited after construction."
                ) from None
        assert isinstance(twin, nn.Module)
        expected = {name: tuple(value.shape) for name, value in twin.state_dict().items()}
        actual = {name: tuple(value.shape) for name, value in state_dict.items()}
        if expected != actual:
            differ = sorted(
                name for name in expected.keys() | actual.keys()
                if expected.get(name) != actual.get(name)
            )  # fmt: skip
            raise CheckpointError(
                f"The weights of this {type(self).__name__} do not fit its config {config} "
                f"(entries {differ[:5]}{'...' if len(differ) > 5 else ''} are missing, extra or "
                "of another shape); nothing was saved. Save a model whose config built it."
            )

    def _card_facts(
        self, card: Mapping[str, Any] | None, scene: SceneSettings | None
    ) -> tuple[SceneSettings | None, dict[str, Any]]:
        """The scene to store and the card's facts with the model's class, scene and planning
        filled in, after checking what the card says of them."""
        facts = plain(dict(card or {}), "model card")
        if facts.get("scene") is not None:
            scene = self._card_scene(facts["scene"], scene)
        facts["model"] = self._card_entry(facts, "model", type(self).__name__)
        if scene is not None:
            facts["scene"] = plain(scene.as_dict(), "scene")
        planning, given = plain(self.planning.as_dict(), "planning"), facts.get("planning", {})
        if not isinstance(given, dict):
            raise ModelCardError(f"The model card's planning {given!r} is no mapping.")
        for key, value in planning.items():
            self._card_entry(given, key, value)
        facts["planning"] = {**given, **planning}
        return scene, facts

    @staticmethod
    def _card_scene(values: Any, scene: SceneSettings | None) -> SceneSettings:
        """The card's scene, checked: it builds, and equals ``scene`` (when known)."""
        card_scene = scene_from(values, "The model card")
        if scene is not None and card_scene != scene:
            raise ModelCardError(
                f"The model card's scene {card_scene} is not the model's {scene}; give the scene "
                "the model was trained on (or leave it out of the card)."
            )
        return card_scene

    @staticmethod
    def _card_entry(facts: Mapping[str, Any], key: str, value: Any) -> Any:
        """``value``, after checking that the card's ``key`` (if given) says the same."""
        if facts.get(key, value) != value:
            raise ModelCardError(
                f"The model card says {key}={facts[key]!r} but the model has {value!r}; fix "
                "the card (it describes this model) or leave the entry out."
            )
        return value

    @classmethod
    def from_checkpoint(
        cls: type[ModelT], path: str | os.PathLike, expected_config: dict[str, Any] | None = None
    ) -> ModelT:
        """Rebuilds a model saved by :meth:`save_checkpoint` (a ``.pt`` file, loaded with
        ``weights_only=True``) or :meth:`save_pretrained` (a model folder).

        Args:
            path: Checkpoint file or model folder.
            expected_config: Constructor settings the caller relies on; any that differ from the
                stored ones raise :class:`CheckpointError`.

        Raises:
            CheckpointError: Missing, corrupt, truncated, foreign or mismatching checkpoint
                (:class:`~kinet_rl.models.hub.NotAModelFolderError`: a folder without a model;
                :class:`~kinet_rl.models.hub.ModelSceneError`: a scene that cannot be built).
        """
        if Path(path).is_dir():
            stored = read_model_config(path)
            state_dict = read_model_weights(path)
        else:
            stored = safe_torch_load(
                path, ("format", "model_config", "state_dict"), f"{cls.__name__}.save_checkpoint"
            )
            state_dict = stored["state_dict"]
        return cls._from_stored(stored, state_dict, path, expected_config)

    @classmethod
    def from_pretrained(
        cls: type[ModelT],
        name_or_folder: str | os.PathLike,
        expected_config: dict[str, Any] | None = None,
        revision: str | None = None,
        token: str | None = None,
    ) -> ModelT:
        """A model from a model folder, in eval mode.

        Args:
            name_or_folder: A local model folder (:meth:`save_pretrained`), a shipped model's
                name (:func:`~kinet_rl.models.pretrained.pretrained_names`), or a Hugging Face
                Hub repo id ``owner/name`` (downloaded; needs ``pip install 'kinet_rl[hub]'``).
            expected_config: As for :meth:`from_checkpoint`.
            revision: The Hub revision (branch, tag or commit) of a repo id.
            token: A Hub token for a private repo.

        Raises:
            CheckpointError: As :meth:`from_checkpoint`.
            HubExtraMissingError: A repo id without ``huggingface_hub`` installed.
            ValueError: Neither a folder, a shipped name nor a repo id.
        """
        folder = model_folder(name_or_folder, revision=revision, token=token)
        model = cls.from_checkpoint(folder, expected_config)
        assert isinstance(model, nn.Module)
        model.eval()
        return model

    @classmethod
    def _from_stored(
        cls: type[ModelT],
        stored: Mapping[str, Any],
        state_dict: Mapping[str, Tensor],
        path: str | os.PathLike,
        expected_config: dict[str, Any] | None,
    ) -> ModelT:
        """The model of a checkpoint's entries (``format``, ``model_config``, ``scene``,
        ``planning``) and weights, checked against the class and ``expected_config``."""
        if stored["format"] != cls.checkpoint_format:
            owner = model_class_of_format(stored["format"])
            use = (
                f"load it with {owner.__name__}"
                if owner
                else "load it with the model class that wrote it"
            )
            raise CheckpointError(
                f"Checkpoint {path} has format {stored['format']!r}, but {cls.__name__} reads "
                f"{cls.checkpoint_format!r}; {use} (kinet_rl.rows.load_trained_model picks the "
                "class by format)."
            )
        config = stored["model_config"]
        diffs = {
            key: (value, config.get(key, "<missing>"))
            for key, value in (expected_config or {}).items()
            if config.get(key, "<missing>") != value
        }
        if diffs:
            detail = ", ".join(
                f"{k}: expected {e!r}, checkpoint {s!r}" for k, (e, s) in diffs.items()
            )
            raise CheckpointError(
                f"Checkpoint {path} does not match the requested model config ({detail}); "
                "use a checkpoint trained with these settings or change the config to match."
            )
        scene = stored.get("scene")
        scene = None if scene is None else scene_from(scene, f"Checkpoint {path}")
        try:
            model = cls(**config)
            assert isinstance(model, nn.Module)
            model.load_state_dict(state_dict)
            planning = stored.get("planning")
            if planning is not None:
                model.planning = PlanningDefaults.from_mapping(planning)
        except (TypeError, RuntimeError, KeyError, ValueError) as err:
            raise CheckpointError(
                f"Checkpoint {path} holds weights that do not fit its model config ({err}); "
                "the file was edited or written by an incompatible version, re-save it."
            ) from err
        model.scene = scene
        return model


def scene_from(values: Any, source: str) -> SceneSettings:
    """The ``SceneSettings`` that ``source`` (a checkpoint or card) names.

    Raises:
        ModelSceneError: The scene cannot be built (names the problem).
    """
    try:
        return SceneSettings.from_mapping(values)
    except (ConfigError, TypeError, ValueError, AttributeError) as err:
        raise ModelSceneError(
            f"{source} names a scene that cannot be built ({err}); the scene must be the "
            "SceneSettings the model was trained on (task, num_objects, camera, image_size...)."
        ) from None


def model_class_of_format(checkpoint_format: str) -> type[ConfigCheckpointMixin] | None:
    """The imported model class that writes ``checkpoint_format`` (None if none does)."""
    pending: list[type[ConfigCheckpointMixin]] = [ConfigCheckpointMixin]
    while pending:
        for subclass in pending.pop().__subclasses__():
            if subclass.__dict__.get("checkpoint_format") == checkpoint_format:
                return subclass
            pending.append(subclass)
    return None


def stored_entries(path: str | os.PathLike) -> dict[str, Any]:
    """What a checkpoint (a ``.pt`` file or a model folder) stores beside its weights: its
    ``format``, ``model_config``, ``scene`` and ``planning``.

    Raises:
        CheckpointError: Not a checkpoint (named).
    """
    if Path(path).is_dir():
        return read_model_config(path)
    state = safe_torch_load(path, ("format",), "save_checkpoint")
    return {key: value for key, value in state.items() if key != "state_dict"}


def checkpoint_scene(path: str | os.PathLike) -> SceneSettings | None:
    """The scene a checkpoint's (or model folder's) model was trained on (None when it does
    not say)."""
    scene = stored_entries(path).get("scene")
    return None if scene is None else scene_from(scene, f"Checkpoint {path}")
