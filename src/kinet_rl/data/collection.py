"""Random-push data collection with TorchRL collectors into resumable on-disk datasets."""

from __future__ import annotations

import functools
import importlib.metadata
import inspect
import logging
import math
import platform
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.collectors import Collector, MultiSyncCollector
from torchrl.collectors.distributed import DistributedCollector
from torchrl.envs import EnvBase, StepCounter
from torchrl.weight_update import NoWeightSyncScheme
from tqdm import tqdm

from kinet_rl.atomic import directory_lock
from kinet_rl.config_schema import check_arguments, check_keys, config_group, invalid, require
from kinet_rl.data.object_counts import check_object_count_range, chunk_envs
from kinet_rl.data.policy import (
    EPISODE_ID,
    STEP_COUNT,
    EpisodeSeeding,
    RandomPushPolicy,
    read_workspace_half_size,
)
from kinet_rl.data.storage import FORMAT_VERSION, METADATA_FILE, EpisodeWriter, read_json
from kinet_rl.interrupts import worker_processes
from kinet_rl.keys import (
    ACTION,
    NEXT_OBJECT_POS,
    NEXT_PIXELS,
    OBJECT_POS,
    OBJECT_SHAPE,
    OBJECT_YAW,
    PIXELS,
    UNSTABLE,
)

logger = logging.getLogger(__name__)

VERSIONED_PACKAGES = ("kinet_rl", "torch", "torchrl", "tensordict", "mujoco", "dm-control", "numpy")
DEFAULT_SPLITS = {"train": 0.8, "val": 0.1, "test": 0.1}
BACKENDS = ("local", "distributed")
# DistributedCollector stops after total_frames (-1 yields nothing there); collect_dataset stops
# it itself once the dataset is full, so it gets a bound it never reaches.
UNBOUNDED_FRAMES = 2**62
# DistributedCollector arguments that make_collector sets itself.
DISTRIBUTED_FIXED_ARGS = ("create_env_fn", "policy", "frames_per_batch", "total_frames", "sync")
#: Seconds the workers get to stop when collection ends or is interrupted (then terminated).
SHUTDOWN_SECONDS = 5.0


def seeded_env(
    env_fn: Callable[[], EnvBase], seed: int, first_episode: int, episode_stride: int
) -> EnvBase:
    """Builds ``env_fn()`` with an :class:`EpisodeSeeding` transform appended (picklable)."""
    env = env_fn()
    env.append_transform(EpisodeSeeding(seed, first_episode, episode_stride))
    return env


def episode_length_of(env: EnvBase) -> int:
    """Returns ``max_steps`` of the env's ``StepCounter`` (the number of pushes per episode)."""
    transforms = getattr(env, "transform", [])
    for transform in transforms if hasattr(transforms, "__iter__") else [transforms]:
        if isinstance(transform, StepCounter) and transform.max_steps is not None:
            return int(transform.max_steps)
    raise ValueError("The env needs a StepCounter(max_steps=T): episodes must have T pushes.")


def split_ranges(num_episodes: int, splits: Mapping[str, float]) -> dict[str, list[int]]:
    """Assigns contiguous episode ranges [start, stop) to splits by cumulative fraction."""
    if not splits or abs(sum(splits.values()) - 1.0) > 1e-6 or min(splits.values()) < 0:
        raise invalid("splits", dict(splits), "fractions of at least 0 that sum to 1")
    ranges, start, cumulative = {}, 0, 0.0
    for name, fraction in splits.items():
        cumulative += fraction
        stop = min(num_episodes, round(cumulative * num_episodes))
        ranges[name] = [start, stop]
        start = stop
    ranges[name][1] = num_episodes
    return ranges


def package_versions() -> dict[str, str]:
    """Versions of the packages that shape the data, plus Python's."""
    versions = {"python": platform.python_version()}
    for name in VERSIONED_PACKAGES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def assemble_episode(rows: TensorDictBase, episode_length: int) -> TensorDictBase | None:
    """Turns one episode's transitions [T] into stored arrays, or None if it must be discarded.

    An episode is discarded when the simulation went unstable or it ended before T pushes.
    """
    rows = rows[rows.get(STEP_COUNT).reshape(-1).argsort()]
    steps = rows.get(STEP_COUNT).reshape(-1)
    if len(rows) != episode_length or not torch.equal(steps, torch.arange(episode_length)):
        return None
    if rows.get(("next", UNSTABLE)).any() or rows.get(UNSTABLE).any():
        return None
    last = rows[-1]
    return TensorDict(
        {
            PIXELS: torch.cat([rows.get(PIXELS), last.get(NEXT_PIXELS)[None]]),
            ACTION: rows.get(ACTION),
            OBJECT_POS: torch.cat([rows.get(OBJECT_POS), last.get(NEXT_OBJECT_POS)[None]]),
            OBJECT_YAW: torch.cat([rows.get(OBJECT_YAW), last.get(("next", OBJECT_YAW))[None]]),
            OBJECT_SHAPE: rows.get(OBJECT_SHAPE)[0],  # constant within the episode
            "source_episode": rows.get(EPISODE_ID)[0, 0],
        }
    )


class EpisodeAssembler:
    """Groups streamed transitions by episode and releases finished episodes in index order.

    Episodes from ``stop`` on are ignored (another collector collects them).
    """

    def __init__(self, first_episode: int, episode_length: int, stop: float = math.inf) -> None:
        self.next_episode = first_episode
        self.episode_length = episode_length
        self.stop = stop
        self._pending: dict[int, list[TensorDictBase]] = {}
        self._finished: dict[int, TensorDictBase | None] = {}

    def add(self, batch: TensorDictBase) -> None:
        """Adds a collector batch of any shape."""
        batch = batch.reshape(-1)
        ids = batch.get(EPISODE_ID).reshape(-1)
        done = batch.get(("next", "done")).reshape(-1)
        for episode in ids.unique().tolist():
            mask = ids == episode
            if episode < self.next_episode or episode in self._finished:
                continue  # already accounted for (resumed run, or a replayed reset)
            if episode >= self.stop:
                continue
            self._pending.setdefault(episode, []).append(batch[mask])
            if done[mask].any():
                rows = torch.cat(self._pending.pop(episode))
                self._finished[episode] = assemble_episode(rows, self.episode_length)

    def pop_ready(self) -> list[tuple[int, TensorDictBase | None]]:
        """Returns (index, episode or None if discarded) for the contiguous finished prefix."""
        ready = []
        while self.next_episode in self._finished:
            ready.append((self.next_episode, self._finished.pop(self.next_episode)))
            self.next_episode += 1
        return ready


def check_backend(backend: str, distributed: Mapping[str, Any] | None) -> None:
    """Raises ``ConfigError`` for an unknown backend or unsettable ``DistributedCollector`` options."""
    require(backend in BACKENDS, "backend", backend, f"one of {BACKENDS}")
    accepted = set(inspect.signature(DistributedCollector).parameters) - set(DISTRIBUTED_FIXED_ARGS)
    check_keys(distributed or {}, accepted, "distributed")  # those kinet_rl lets you set


def check_collection(
    num_episodes: int,
    num_workers: int,
    chunk_episodes: int,
    splits: Mapping[str, float],
    policy: Mapping[str, Any],
    max_discard_fraction: float,
    backend: str,
    distributed: Mapping[str, Any] | None,
    num_objects_range: Sequence[int] | None = None,
) -> None:
    """Raises (``ConfigError`` naming the argument) for :func:`collect_dataset` arguments it
    would refuse; builds nothing, so a config can be checked before any collection."""
    for name, value in (
        ("num_episodes", num_episodes),
        ("num_workers", num_workers),
        ("chunk_episodes", chunk_episodes),
    ):
        require(value >= 1, name, value, "an integer of at least 1")
    require(
        0.0 <= max_discard_fraction <= 1.0,
        "max_discard_fraction",
        max_discard_fraction,
        "a number in [0, 1]",
    )
    split_ranges(num_episodes, splits)
    with config_group("policy"):
        args = check_arguments(RandomPushPolicy, policy, exclude=["workspace_half_size"])
        RandomPushPolicy(1.0, **args)  # its own range checks
    check_backend(backend, distributed)
    check_object_count_range(num_objects_range)


def make_collector(
    env_fn: Callable[[], EnvBase],
    policy: RandomPushPolicy,
    seed: int,
    first_episode: int,
    num_workers: int,
    episode_length: int,
    backend: str = "local",
    distributed: Mapping[str, Any] | None = None,
) -> Collector | MultiSyncCollector | DistributedCollector:
    """Builds the collector that streams transitions of episodes ``first_episode, ...``.

    ``backend="local"``: one ``Collector`` in process (1 worker) or a ``MultiSyncCollector`` of
    worker processes. ``backend="distributed"``: TorchRL's ``DistributedCollector`` over
    torch.distributed (one node per worker, synchronous), with ``distributed`` as extra
    arguments; ``launcher="mp"`` (default) starts the nodes on this machine, ``"submitit"`` or
    ``"submitit_delayed"`` on a SLURM cluster. Worker ``w`` collects episodes
    ``first_episode + w + k * num_workers`` with either backend.
    """
    check_backend(backend, distributed)
    env_fns = [
        functools.partial(seeded_env, env_fn, seed, first_episode + w, num_workers)
        for w in range(num_workers)
    ]
    common = {"total_frames": -1, "auto_register_policy_transforms": False}
    if backend == "distributed":
        options = {"launcher": "mp", **(distributed or {})}
        node_kwargs = options.pop("collector_kwargs", None) or {}
        return DistributedCollector(
            env_fns,
            policy,
            frames_per_batch=episode_length * num_workers,
            total_frames=UNBOUNDED_FRAMES,
            sync=True,
            collector_kwargs={"auto_register_policy_transforms": False, **node_kwargs},
            **options,
        )
    if num_workers == 1:
        return Collector(env_fns[0], policy, frames_per_batch=episode_length, **common)
    # The random-push policy has no weights to send; the default shared-memory scheme would
    # also hang the interpreter's exit after an interrupt (its finalizer starts a thread).
    return MultiSyncCollector(
        env_fns,
        policy,
        frames_per_batch=episode_length * num_workers,
        weight_sync_schemes={"policy": NoWeightSyncScheme()},
        **common,
    )


def collect_dataset(
    env_fn: Callable[..., EnvBase],
    env_config: Mapping[str, Any],
    root: str | Path = "data",
    name: str = "blocks_top64",
    num_episodes: int = 200,
    seed: int = 0,
    num_workers: int = 2,
    chunk_episodes: int = 16,
    splits: Mapping[str, float] | None = None,
    policy: Mapping[str, Any] | None = None,
    workspace_half_size: float | None = None,
    max_discard_fraction: float = 0.5,
    progress: bool = True,
    backend: str = "local",
    distributed: Mapping[str, Any] | None = None,
    num_objects_range: tuple[int, int] | None = None,
) -> Path:
    """Collects ``num_episodes`` random-push episodes into ``<root>/<name>``; resumes if partial.

    Episode ``i`` of the run is fully determined by ``(seed, i)``: the same seed gives the same
    dataset for any ``num_workers``, and an interrupted run continues from its last committed
    episode. Ctrl-C or SIGTERM commits the finished episodes, then stops the workers (within
    ``SHUTDOWN_SECONDS``) and raises ``KeyboardInterrupt``. Unstable episodes are discarded,
    counted, and replaced by later ones. The folder is locked while collecting.

    Args:
        env_fn: picklable zero-argument env factory (e.g. ``functools.partial(make_env, ...)``);
            with ``num_objects_range`` it must also take ``num_objects=``.
        env_config: the env's settings, recorded in the metadata and checked by ``load_dataset``.
        root: folder holding datasets (relative paths are relative to the working directory).
        name: dataset folder name.
        num_episodes: stable episodes to keep.
        seed: seed of the run.
        num_workers: env worker processes (1 collects in this process).
        chunk_episodes: episodes written per commit (the most work a killed process loses).
        splits: fractions per split name, assigned as contiguous episode ranges.
        policy: keyword arguments of :class:`RandomPushPolicy` (without the workspace size).
        workspace_half_size: metres; read from the env when None.
        max_discard_fraction: abort if more than this fraction of episodes is unstable.
        progress: show a tqdm progress bar.
        backend: ``"local"`` (this machine's processes) or ``"distributed"`` (TorchRL's
            ``DistributedCollector``; see :func:`make_collector`). Both give the same data.
        distributed: extra ``DistributedCollector`` arguments for ``backend="distributed"``,
            e.g. ``{"launcher": "submitit", "tcp_port": 10003, "slurm_kwargs": {...}}``.
        num_objects_range: ``(low, high)``: each chunk of ``chunk_episodes`` source episodes
            gets an object count in [low, high] drawn from ``(seed, chunk)`` and is collected
            by a fresh collector on ``env_fn(num_objects=count)``; stored with NaN padding to
            ``high`` objects and a per-episode count (:mod:`kinet_rl.data.object_counts`).
            None: every episode has the env's count.

    Returns:
        The dataset folder.

    Raises:
        DirectoryInUseError: Another process is collecting into the same folder.
        DiskFullError: The disk cannot hold the dataset (checked before collecting).
    """
    path = Path(root) / name
    if (path / METADATA_FILE).exists():
        logger.info("Dataset %s is already complete; nothing to collect.", path)
        return path
    splits = dict(DEFAULT_SPLITS if splits is None else splits)
    check_collection(
        num_episodes,
        num_workers,
        chunk_episodes,
        splits,
        policy or {},
        max_discard_fraction,
        backend,
        distributed,
        num_objects_range,
    )
    with directory_lock(path, "collecting a dataset"):
        if (path / METADATA_FILE).exists():  # completed by the process that held the lock
            return path
        ranges = split_ranges(num_episodes, splits)
        probe = env_fn() if num_objects_range is None else env_fn(num_objects=num_objects_range[1])
        try:
            episode_length = episode_length_of(probe)
            image_size = int(probe.observation_spec[PIXELS].shape[-2])
            num_objects = int(probe.observation_spec[OBJECT_POS].shape[-2])
            if workspace_half_size is None:
                workspace_half_size = read_workspace_half_size(probe)
        finally:
            probe.close()
        push_policy = RandomPushPolicy(workspace_half_size, **(policy or {}))
        settings = {
            "env": dict(env_config),
            "seed": seed,
            "num_episodes": num_episodes,
            "episode_length": episode_length,
            "image_size": image_size,
            "num_objects": num_objects,
            "workspace_half_size": workspace_half_size,
            "policy": dict(policy or {}),
            "splits": splits,
        }
        if num_objects_range is not None:  # both decide which episode gets which count
            settings["num_objects_range"] = list(num_objects_range)
            settings["chunk_episodes"] = chunk_episodes
        writer = EpisodeWriter(
            path,
            num_episodes,
            episode_length,
            image_size,
            num_objects,
            settings,
            variable_object_count=num_objects_range is not None,
        )
        bar = tqdm(total=num_episodes, initial=writer.committed, desc=name, disable=not progress)
        start = time.perf_counter()
        parts: Iterable[tuple[Callable[[], EnvBase], float]] = [(env_fn, math.inf)]
        if num_objects_range is not None:  # one collector per chunk, on an env of its count
            parts = chunk_envs(env_fn, seed, chunk_episodes, num_objects_range, writer.processed)
        try:
            for part_env_fn, stop in parts:
                if writer.committed == num_episodes:
                    break
                start_collector = functools.partial(
                    make_collector,
                    part_env_fn,
                    push_policy,
                    seed,
                    writer.processed,
                    num_workers,
                    episode_length,
                    backend=backend,
                    distributed=distributed,
                )
                with worker_processes(
                    start_collector, lambda collector: collector.shutdown(timeout=SHUTDOWN_SECONDS)
                ) as collector:
                    fill_writer(
                        writer,
                        collector,
                        episode_length,
                        chunk_episodes,
                        max_discard_fraction,
                        bar,
                        stop,
                    )
        finally:
            bar.close()
        writer.finalize(
            {
                "format_version": FORMAT_VERSION,
                "complete": True,
                "name": name,
                **settings,
                "splits": ranges,
                "split_fractions": splits,
                "num_workers": num_workers,
                "backend": backend,
                "discarded_unstable": writer.discarded,
                "processed_episodes": writer.processed,
                "arrays": list(writer.specs),
                "versions": package_versions(),
                "collection_seconds_last_run": time.perf_counter() - start,
            }
        )
    logger.info("Dataset %s complete: %s", path, read_json(path / METADATA_FILE)["splits"])
    return path


def fill_writer(
    writer: EpisodeWriter,
    collector: Iterable[TensorDictBase],
    episode_length: int,
    chunk_episodes: int,
    max_discard_fraction: float,
    bar: tqdm,
    stop: float = math.inf,
) -> None:
    """Commits the collector's stable episodes to ``writer`` until it is full or the source
    episodes before ``stop`` are all processed.

    Episodes are committed in chunks of ``chunk_episodes``, and the open chunk when ``stop`` is
    reached. A Ctrl-C or SIGTERM that arrives while waiting for the collector (nearly all of the
    time) first commits the finished episodes of the open chunk, so that no completed episode
    is lost.
    """
    assembler = EpisodeAssembler(writer.processed, episode_length, stop)
    discarded = writer.discarded
    buffer: list[TensorDictBase] = []
    batches = iter(collector)
    while writer.committed < writer.num_episodes and assembler.next_episode < stop:
        try:
            batch = next(batches)
        except KeyboardInterrupt:
            if buffer:  # every popped episode is handled: the state is consistent here
                writer.commit(torch.stack(buffer), assembler.next_episode, discarded)
                logger.info("Interrupted: %s kept at %d episodes.", writer.path, writer.committed)
            raise
        assembler.add(batch)
        for index, episode in assembler.pop_ready():
            if episode is None:
                discarded += 1
            else:
                buffer.append(episode)
            full = writer.committed + len(buffer) == writer.num_episodes
            if len(buffer) == chunk_episodes or full or index + 1 == stop:
                writer.commit(torch.stack(buffer) if buffer else None, index + 1, discarded)
                bar.update(len(buffer))
                buffer = []
            if full:
                break
        if writer.committed < writer.num_episodes and discarded > max(
            10, max_discard_fraction * assembler.next_episode
        ):
            raise RuntimeError(
                f"{discarded} of {assembler.next_episode} episodes went unstable; check the "
                "env's physics settings (kept data so far is in place and will resume)."
            )
