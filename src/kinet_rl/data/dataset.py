"""Fast random access to collected push datasets: transitions and short sequences."""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase

from kinet_rl.data.storage import (
    COLLECT_HINT,
    FORMAT_VERSION,
    METADATA_FILE,
    PROGRESS_FILE,
    DatasetCorruptError,
    DatasetIncompleteError,
    DatasetMismatchError,
    DatasetNotFoundError,
    check_array_files,
    open_episodes,
    read_json,
    stored_array_specs,
)
from kinet_rl.keys import (
    ACTION,
    EPISODE,
    FUTURE_ACTION,
    FUTURE_PIXELS,
    OBJECT_COUNT,
    OBJECT_POS,
    OBJECT_SHAPE,
    OBJECT_YAW,
    PIXELS,
    PIXELS_0,
    STEP,
)

logger = logging.getLogger(__name__)

ALL_SPLITS = "all"
REQUIRED_METADATA = ("env", "splits", "num_episodes", "episode_length", "image_size", "num_objects")
#: Recorded collection settings of the ``data`` group that ``expect`` can name (null if absent).
DATA_SETTINGS = ("num_objects_range",)


def _override(key: str, value: Any) -> str:
    """The command-line override that collects a dataset with ``key`` set to ``value``."""
    if key in DATA_SETTINGS:
        return f"data.{key}={json.dumps(value, separators=(',', ':'))}"
    return f"env.{key}={value}"


def _check_expectations(path: Path, metadata: Mapping[str, Any], expect: Mapping[str, Any]) -> None:
    env = metadata["env"]
    recorded = {**env, **{k: metadata[k] for k in ("image_size", "num_objects") if k in metadata}}
    recorded |= {k: metadata.get(k) for k in DATA_SETTINGS}
    unknown = sorted(set(expect) - set(recorded))
    if unknown:
        raise ValueError(
            f"expect has keys {unknown} that the dataset does not record; known: {sorted(recorded)}."
        )
    wrong = {k: v for k, v in expect.items() if recorded[k] != v}
    if wrong:
        have = ", ".join(f"{k}={recorded[k]!r}" for k in wrong)
        want = ", ".join(f"{k}={v!r}" for k, v in wrong.items())
        overrides = " ".join(_override(k, v) for k, v in wrong.items())
        raise DatasetMismatchError(
            f"Dataset {path} has {have} but the caller expects {want}. Collect a matching "
            f"dataset (e.g. `python -m kinet_rl.collect {overrides} data.name=<new name>`) "
            "or point to one that matches."
        )


def _rows(stored: torch.Tensor) -> torch.Tensor:
    """Plain-tensor 2-D view [E * T', D] of a memmapped [E, T', ...] array (no copy)."""
    return stored.as_subclass(torch.Tensor).flatten(2).flatten(0, 1)


class PushDataset:
    """Random-push transitions of one split, gathered with index_select from memmapped rows.

    Args:
        path: dataset folder ``<root>/<name>`` written by :func:`collect_dataset`.
        split: ``"train"``, ``"val"``, ``"test"`` (or another recorded split), or ``"all"``.
        expect: recorded settings the caller relies on, e.g. ``{"image_size": 64,
            "camera": "top", "task": "blocks", "num_objects_range": None}``; any difference
            raises :class:`DatasetMismatchError`.

    A variable-count dataset (collected with ``num_objects_range``) stores ``num_objects`` =
    N, the most objects an episode holds; its batches' per-object entries (``object_pos``,
    ``object_yaw``, ``object_shape``) are NaN for the objects beyond an episode's count.

    A dataset without object state (pixels and pushes only, e.g. a robot's recordings imported
    with ``python -m kinet_rl.import_data``) has ``num_objects`` None and batches without the
    per-object entries; :meth:`check_keys` refuses it to a model that reads them.
    """

    path: Path | None  # None for in-memory episodes (:meth:`from_episodes`)

    def __init__(
        self, path: str | Path, split: str = "train", expect: Mapping[str, Any] | None = None
    ) -> None:
        self.path = path = Path(path)
        if not (path / METADATA_FILE).exists():
            if (path / PROGRESS_FILE).exists():
                progress = read_json(path / PROGRESS_FILE)
                raise DatasetIncompleteError(
                    f"Dataset {path} is partial ({progress.get('committed')}/"
                    f"{progress.get('num_episodes')} episodes) and not marked complete. Rerun the "
                    "collect command that created it, with the same settings, to resume it."
                )
            raise DatasetNotFoundError(f"No dataset at {path}. Collect it with: {COLLECT_HINT}")
        self.metadata = metadata = read_json(path / METADATA_FILE)
        if metadata.get("format_version") != FORMAT_VERSION or not metadata.get("complete"):
            raise DatasetCorruptError(
                f"{path / METADATA_FILE} has format {metadata.get('format_version')} "
                f"(complete={metadata.get('complete')}); this kinet_rl reads format "
                f"{FORMAT_VERSION}. Collect it again: {COLLECT_HINT}"
            )
        missing = [key for key in REQUIRED_METADATA if key not in metadata]
        if missing:
            raise DatasetCorruptError(
                f"{path / METADATA_FILE} lacks {missing}. Delete {path} and collect it again: "
                f"{COLLECT_HINT}"
            )
        if expect:
            _check_expectations(path, metadata, expect)
        splits = {**metadata["splits"], ALL_SPLITS: [0, metadata["num_episodes"]]}
        if split not in splits:
            raise ValueError(f"Unknown split {split!r}; {path} has {sorted(splits)}.")
        self.split = split
        check_array_files(path, metadata["num_episodes"], stored_array_specs(metadata))
        self._attach(open_episodes(path), *splits[split])
        if self.num_episodes < 1:
            raise ValueError(f"Split {split!r} of {path} holds no episodes.")

    @classmethod
    def from_episodes(cls, episodes: TensorDictBase) -> PushDataset:
        """A dataset of episodes held in memory, as one split ``"all"`` (no files, no metadata).

        Args:
            episodes: TensorDict [E] with the stored arrays' keys and shapes (see
                :mod:`kinet_rl.data.storage`), e.g. stacked
                :func:`~kinet_rl.data.collection.assemble_episode` outputs.
        """
        if episodes.batch_dims != 1 or episodes.shape[0] < 1:
            raise ValueError(
                f"episodes must be a TensorDict [E] with E >= 1, got {episodes.shape}."
            )
        dataset = cls.__new__(cls)
        dataset.path, dataset.metadata, dataset.split = None, {}, ALL_SPLITS
        dataset._attach(episodes, 0, episodes.shape[0])
        return dataset

    def _attach(self, stored: TensorDictBase, start: int, stop: int) -> None:
        """Reads episodes ``start:stop`` of the stored arrays [E, ...]."""
        self.episode_length = stored[ACTION].shape[1]
        self.image_size = stored[PIXELS].shape[2]
        positions = stored.get(OBJECT_POS, None)  # absent from datasets without object state
        #: Objects per scene N, or None for a dataset without object state.
        self.num_objects = None if positions is None else positions.shape[2]
        # Row views of the memory maps, indexed with index_select: one row per frame or push
        # (about 9x faster than advanced indexing of the [E, T+1, H, W, 3] tensor).
        self._frames = _rows(stored[PIXELS])  # [E * (T+1), H * W * 3]
        self._actions = _rows(stored[ACTION])  # [E * T, 4]
        self._object_pos = None if positions is None else _rows(positions)  # [E * (T+1), N * 2]
        self._object_yaw = None if positions is None else _rows(stored[OBJECT_YAW])  # [.., N]
        shapes = stored.get(OBJECT_SHAPE, None)  # absent from datasets of older versions
        self._object_shape = None if shapes is None else shapes.as_subclass(torch.Tensor)
        counts = stored.get(OBJECT_COUNT, None)  # stored by variable-count datasets only
        #: Objects of each stored episode ``[E]``, or None when every episode holds N.
        self.object_counts = None if counts is None else counts.as_subclass(torch.Tensor)
        self.stored_keys = frozenset(stored.keys())
        self.episode_start, self.episode_stop = start, stop
        self.num_episodes = stop - start

    def check_keys(self, keys: Iterable[str], user: str) -> None:
        """Raises :class:`DatasetMismatchError` if the dataset stores no array ``user`` needs.

        Args:
            keys: the stored arrays (e.g. ``OBJECT_SHAPE``) that ``user`` reads.
            user: who needs them, for the message (e.g. the model's class name).
        """
        missing = sorted(set(keys) - self.stored_keys)
        if not missing:
            return
        if not self.has_object_state:
            source = "these in-memory episodes" if self.path is None else f"dataset {self.path}"
            raise DatasetMismatchError(
                f"{user} needs {missing}, but {source} holds pixels and pushes only, no object "
                f"state (e.g. a robot's recordings, imported). {user} learns from ground-truth "
                "object state; train a model that learns from pixels alone on it (KINet: "
                "model=kinet loss=kinet; V-CDN, Forw, ForwInv), or collect simulated data for "
                f"{user}: {COLLECT_HINT}"
            )
        if self.path is None:
            raise DatasetMismatchError(
                f"{user} needs {missing}, which these in-memory episodes lack; assemble them "
                "from an env that observes them (kinet_rl.envs.make_env does)."
            )
        raise DatasetMismatchError(
            f"{user} needs {missing}, which dataset {self.path} does not store (it was collected "
            f"by an older kinet_rl). Delete {self.path} and collect it again: {COLLECT_HINT}"
        )

    def check_fixed_object_count(self, user: str) -> None:
        """Raises :class:`DatasetMismatchError` if the episodes hold different object counts.

        Args:
            user: who needs one object count in every episode, for the message (e.g. the
                model's class name).
        """
        if self.object_counts is None:
            return
        low, high = int(self.object_counts.min()), int(self.object_counts.max())
        source = "these in-memory episodes" if self.path is None else f"dataset {self.path}"
        raise DatasetMismatchError(
            f"{user} needs the same object count in every episode, but {source} holds {low} to "
            f"{high} objects per episode (collected with data.num_objects_range; the missing "
            f"objects are NaN). Train a keypoint model (KINet, V-CDN) on it, or collect a "
            f"fixed-count dataset for {user}: {COLLECT_HINT} data.num_objects_range=null "
            "env.num_objects=<N>."
        )

    @property
    def has_object_state(self) -> bool:
        """Whether the episodes store object positions (a dataset of pixels and pushes only, e.g.
        imported from a robot, does not)."""
        return self._object_pos is not None

    def _objects(self, rows: torch.Tensor) -> dict[str, torch.Tensor]:
        """``{OBJECT_POS: [*R, N, 2], OBJECT_YAW: [*R, N]}`` at frame rows ``rows`` [*R], or
        ``{}`` for a dataset without object state."""
        if self._object_pos is None or self._object_yaw is None or self.num_objects is None:
            return {}
        n = self.num_objects
        flat = rows.reshape(-1)
        return {
            OBJECT_POS: self._object_pos.index_select(0, flat).view(*rows.shape, n, 2),
            OBJECT_YAW: self._object_yaw.index_select(0, flat).view(*rows.shape, n),
        }

    def _shapes(self, episode: torch.Tensor) -> dict[str, torch.Tensor]:
        """``{OBJECT_SHAPE: [B, N, 8]}`` of ``episode`` [B], or ``{}`` if the dataset has none."""
        if self._object_shape is None:
            return {}
        return {OBJECT_SHAPE: self._object_shape.index_select(0, episode)}

    def __len__(self) -> int:
        """Number of transitions in the split."""
        return self.num_episodes * self.episode_length

    def transitions(
        self, episode: torch.Tensor, step: torch.Tensor, horizon: int = 1
    ) -> TensorDict:
        """Transitions at dataset episode indices ``episode`` [B] and push indices ``step`` [B].

        Returns:
            TensorDict [B]: ``pixels_0``, ``pixels``, (``next``, ``pixels``) uint8 [B, H, W, 3];
            ``action`` [B, 4]; ``object_pos``, (``next``, ``object_pos``) [B, N, 2];
            ``object_yaw``, (``next``, ``object_yaw``) [B, N] (when the dataset has object state);
            ``object_shape`` [B, N, 8] (when the dataset stores it); ``episode``, ``step`` int64
            [B]. With ``horizon`` > 1 (``step + horizon`` within the
            episode) also the ``horizon - 1`` pushes that follow: (``future``, ``action``)
            [B, horizon - 1, 4] and the frames after them, (``future``, ``pixels``)
            [B, horizon - 1, H, W, 3].
        """
        batch, h = len(episode), self.image_size
        times = torch.stack([torch.zeros_like(step), step, step + 1], dim=1)  # [B, 3]
        rows = self._frame_rows(episode[:, None], times)  # [B, 3]
        frames = self._frames.index_select(0, rows.reshape(-1)).view(batch, 3, h, h, 3)
        objects = self._objects(rows[:, 1:])  # [B, 2, N, ...] each, or none
        out = TensorDict(
            {
                PIXELS_0: frames[:, 0],
                PIXELS: frames[:, 1],
                ACTION: self._actions.index_select(0, episode * self.episode_length + step),
                **{key: value[:, 0] for key, value in objects.items()},
                **self._shapes(episode),
                EPISODE: episode,
                STEP: step,
                "next": {
                    PIXELS: frames[:, 2],
                    **{key: value[:, 1] for key, value in objects.items()},
                },
            },
            batch_size=[batch],
        )
        if horizon > 1:
            ahead = step[:, None] + torch.arange(1, horizon)  # [B, horizon - 1] push indices
            frame_rows = self._frame_rows(episode[:, None], ahead + 1).reshape(-1)
            push_rows = (episode[:, None] * self.episode_length + ahead).reshape(-1)
            out[FUTURE_PIXELS] = self._frames.index_select(0, frame_rows).view(
                batch, horizon - 1, h, h, 3
            )
            out[FUTURE_ACTION] = self._actions.index_select(0, push_rows).view(
                batch, horizon - 1, 4
            )
        return out

    def _frame_rows(self, episode: torch.Tensor, time: torch.Tensor) -> torch.Tensor:
        """Row index of frame ``time`` of ``episode`` in the flattened frame arrays."""
        return episode * (self.episode_length + 1) + time

    def _random_episodes(self, batch_size: int, generator: torch.Generator | None) -> torch.Tensor:
        offsets = torch.randint(self.num_episodes, (batch_size,), generator=generator)
        return self.episode_start + offsets

    def sample(
        self,
        batch_size: int,
        generator: torch.Generator | None = None,
        steps_per_episode: int = 1,
        horizon: int = 1,
    ) -> TensorDict:
        """Samples ``batch_size`` transitions uniformly from the split (see :meth:`transitions`).

        With ``steps_per_episode`` > 1 the batch holds ``batch_size / steps_per_episode`` random
        episodes with that many distinct random steps each (negatives of a contrastive loss from
        the same episode). With ``horizon`` > 1 every transition also carries the ``horizon - 1``
        pushes and frames that follow it (a multi-step rollout loss).
        """
        if not 1 <= horizon <= self.episode_length:
            raise ValueError(f"horizon must lie in [1, {self.episode_length}], got {horizon}.")
        offsets, step = sample_steps(
            self.num_episodes,
            self.episode_length - horizon + 1,
            batch_size,
            steps_per_episode,
            generator,
        )
        return self.transitions(self.episode_start + offsets, step, horizon)

    def sample_sequences(
        self, batch_size: int, length: int, generator: torch.Generator | None = None
    ) -> TensorDict:
        """Samples ``batch_size`` windows of ``length`` consecutive pushes.

        Returns:
            TensorDict [B]: ``pixels`` uint8 [B, L+1, H, W, 3] (frames before each push and after
            the last), ``action`` [B, L, 4], ``object_pos`` [B, L+1, N, 2] and ``object_yaw``
            [B, L+1, N] (when the dataset has object state), ``object_shape`` [B, N, 8] (when the
            dataset stores it), ``pixels_0``
            [B, H, W, 3] (the episode's first frame), ``episode`` and ``step`` (first push) [B].
        """
        if not 1 <= length <= self.episode_length:
            raise ValueError(f"length must lie in [1, {self.episode_length}], got {length}.")
        episode = self._random_episodes(batch_size, generator)
        step = torch.randint(self.episode_length - length + 1, (batch_size,), generator=generator)
        h = self.image_size
        times = step[:, None] + torch.arange(length + 1)  # [B, L+1]
        frame_rows = self._frame_rows(episode[:, None], times)  # [B, L+1]
        rows = frame_rows.reshape(-1)  # [B * (L+1)]
        first_rows = self._frame_rows(episode, torch.zeros_like(episode))  # [B]
        push_rows = (episode[:, None] * self.episode_length + times[:, :-1]).reshape(-1)
        return TensorDict(
            {
                PIXELS: self._frames.index_select(0, rows).view(batch_size, length + 1, h, h, 3),
                ACTION: self._actions.index_select(0, push_rows).view(batch_size, length, 4),
                **self._objects(frame_rows),
                **self._shapes(episode),
                PIXELS_0: self._frames.index_select(0, first_rows).view(batch_size, h, h, 3),
                EPISODE: episode,
                STEP: step,
            },
            batch_size=[batch_size],
        )

    def batches(
        self, batch_size: int, shuffle: bool = True, generator: torch.Generator | None = None
    ) -> Iterator[TensorDict]:
        """Iterates once over every transition of the split (the last batch may be smaller)."""
        count = len(self)
        order = torch.randperm(count, generator=generator) if shuffle else torch.arange(count)
        for chunk in order.split(batch_size):
            episode = self.episode_start + chunk // self.episode_length
            step = chunk % self.episode_length
            yield self.transitions(episode, step)


def sample_steps(
    num_episodes: int,
    episode_length: int,
    batch_size: int,
    steps_per_episode: int = 1,
    generator: torch.Generator | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Random ``(episode, step)`` pairs ``[B]``, ``steps_per_episode`` distinct steps per episode.

    With ``steps_per_episode == 1`` episodes and steps are independent and uniform.
    """
    if steps_per_episode == 1:
        episode = torch.randint(num_episodes, (batch_size,), generator=generator)
        return episode, torch.randint(episode_length, (batch_size,), generator=generator)
    if batch_size % steps_per_episode or not 1 <= steps_per_episode <= episode_length:
        raise ValueError(
            f"steps_per_episode={steps_per_episode} must divide batch_size={batch_size} and lie in "
            f"[1, {episode_length}] (the episode length)."
        )
    groups = batch_size // steps_per_episode
    episode = torch.randint(num_episodes, (groups,), generator=generator)
    steps = torch.rand(groups, episode_length, generator=generator).argsort(-1)
    steps = steps[:, :steps_per_episode]
    return episode.repeat_interleave(steps_per_episode), steps.reshape(-1)


def load_dataset(
    path: str | Path, split: str = "train", expect: Mapping[str, Any] | None = None
) -> PushDataset:
    """Opens a complete dataset's split; see :class:`PushDataset` for the arguments and errors."""
    return PushDataset(path, split=split, expect=expect)
