"""Datasets whose episodes hold different numbers of objects (paper, Fig. 9c: 1 to 5 objects).

Collection with ``num_objects_range=(low, high)`` splits the run's source episodes into chunks
of ``chunk_episodes`` consecutive indices (discarded episodes included); chunk ``c`` draws its
object count from ``(seed, c)`` alone and is collected on an env built with that count. So the
same seed gives the same counts for any number of workers, and a resumed run continues with the
counts it started with. Stored per-object arrays are padded with NaN up to ``high`` objects and
``num_objects`` [E] records each episode's count.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator, Sequence

import numpy as np
import torch
import torch.nn.functional as F
from tensordict import TensorDictBase
from torchrl.envs import EnvBase

from kinet_rl.config_schema import require
from kinet_rl.envs.settings import MAX_OBJECTS
from kinet_rl.keys import OBJECT_COUNT, OBJECT_POS, OBJECT_SHAPE, OBJECT_YAW

#: Per-object stored arrays and the dimension, counted from the end, that indexes their objects.
OBJECT_DIMS = {OBJECT_POS: -2, OBJECT_YAW: -1, OBJECT_SHAPE: -2}
#: Spawn key of the object-count draws, which keeps them apart from the episode seeds.
OBJECT_COUNT_STREAM = 1


def check_object_count_range(num_objects_range: Sequence[int] | None) -> None:
    """Raises ``ConfigError`` unless the range is null or ``[low, high]`` within 1..MAX_OBJECTS."""
    if num_objects_range is None:
        return
    bounds = list(num_objects_range)
    require(
        len(bounds) == 2 and 1 <= bounds[0] <= bounds[1] <= MAX_OBJECTS,
        "num_objects_range",
        bounds,
        f"null (one count, env.num_objects) or [low, high] with 1 <= low <= high <= {MAX_OBJECTS}",
    )


def chunk_object_count(seed: int, chunk: int, num_objects_range: Sequence[int]) -> int:
    """The object count of chunk ``chunk`` of a run seeded with ``seed``, uniform in the range."""
    low, high = num_objects_range
    entropy = np.random.SeedSequence([seed, chunk], spawn_key=(OBJECT_COUNT_STREAM,))
    return int(np.random.default_rng(entropy).integers(low, high + 1))


def chunk_envs(
    env_fn: Callable[..., EnvBase],
    seed: int,
    chunk_episodes: int,
    num_objects_range: Sequence[int],
    first_episode: int,
) -> Iterator[tuple[Callable[[], EnvBase], int]]:
    """``(env factory, stop)`` of each chunk, from the one holding ``first_episode`` on, endless:
    ``env_fn`` with the chunk's object count, and the source episode index after the chunk."""
    chunk = first_episode // chunk_episodes
    while True:
        count = chunk_object_count(seed, chunk, num_objects_range)
        yield functools.partial(env_fn, num_objects=count), (chunk + 1) * chunk_episodes
        chunk += 1


def pad_objects(episodes: TensorDictBase, num_objects: int) -> TensorDictBase:
    """Episodes ``[k]`` of one object count with their per-object arrays NaN-padded to
    ``num_objects`` objects and that count stored as ``num_objects`` int64 ``[k]``."""
    count = episodes.get(OBJECT_POS).shape[-2]
    if count > num_objects:
        raise ValueError(f"Episodes of {count} objects do not fit a {num_objects}-object dataset.")
    padded = episodes.clone(recurse=False)
    for key, dim in OBJECT_DIMS.items():
        value = episodes.get(key, None)
        if value is not None:
            widths = [0, 0] * (-dim - 1) + [0, num_objects - count]
            padded.set(key, F.pad(value, widths, value=float("nan")))
    padded.set(OBJECT_COUNT, torch.full(episodes.batch_size, count, dtype=torch.int64))
    return padded
