"""Loader throughput: batches/s of ``PushDataset.sample`` against in-memory gathering.

Usage: ``python bench/loader_throughput.py [--episodes 200] [--steps 60] [--image-size 64]``

Writes a synthetic dataset of realistic size with the real storage writer
(``EpisodeWriter``: random frames, actions and poses) into a temporary folder, opens it with
``load_dataset`` and times ``sample(32)`` and ``sample_sequences(8, 10)``. After a warm-up
pass the memmaps sit in the page cache, which is the regime the issue's target
(>= 1,000 batches/s of 32 transitions at 64 px) refers to. The baseline gathers the same
frames, actions and poses with ``index_select`` from plain tensors held in memory, with no
TensorDict (naive advanced indexing of the in-memory tensors is printed for reference).
Both run alternately for several rounds in one process; medians are reported. The last line is
``ratio: X`` = ``sample(32)`` batches/s over baseline batches/s (1.0 = no loader overhead).

``--lerobot`` also exports the dataset to LeRobot v3 without its object state, imports it
(``python -m kinet_rl.import_data``'s path) and times ``sample(32)`` on the import beside the
native one: ``import ratio: X`` = imported batches/s over native (the own-data issue's target:
>= 0.95).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import torch
from tensordict import TensorDict

from kinet_rl.data import (
    ImportSettings,
    import_push_folder,
    load_dataset,
    plan_import,
    split_ranges,
)
from kinet_rl.data.lerobot import read_lerobot
from kinet_rl.data.lerobot_writer import export_lerobot
from kinet_rl.data.storage import FORMAT_VERSION, EpisodeWriter, episode_array_specs

NUM_OBJECTS = 3
BATCH = 32


def write_synthetic_dataset(path: Path, episodes: int, steps: int, image_size: int) -> None:
    """Writes ``episodes`` random episodes with ``EpisodeWriter`` and marks the set complete."""
    specs = episode_array_specs(steps, image_size, NUM_OBJECTS)
    settings = {
        "env": {"task": "synthetic", "camera": "top", "image_size": image_size},
        "num_episodes": episodes,
        "episode_length": steps,
        "image_size": image_size,
        "num_objects": NUM_OBJECTS,
        "workspace_half_size": 0.20,
    }
    writer = EpisodeWriter(path, episodes, steps, image_size, NUM_OBJECTS, settings)
    generator = torch.Generator().manual_seed(0)
    chunk = 16
    for start in range(0, episodes, chunk):
        count = min(chunk, episodes - start)
        arrays = {}
        for name, (shape, dtype) in specs.items():
            if dtype == torch.uint8:
                arrays[name] = torch.randint(
                    0, 256, (count, *shape), dtype=dtype, generator=generator
                )
            elif dtype == torch.int64:
                arrays[name] = torch.arange(start, start + count)
            else:
                arrays[name] = torch.rand((count, *shape), generator=generator) * 2 - 1
        writer.commit(TensorDict(arrays, batch_size=[count]), start + count, 0)
    writer.finalize(
        {
            "format_version": FORMAT_VERSION,
            "complete": True,
            **settings,
            "splits": split_ranges(episodes, {"train": 0.8, "val": 0.1, "test": 0.1}),
        }
    )


def in_memory_baselines(path: Path, steps: int) -> dict[str, Callable[[torch.Generator], object]]:
    """Samplers gathering the same arrays (3 frames, action, 2 poses) from in-memory tensors.

    ``index_select`` gathers rows of flattened copies (the loader's method, minus the memmap
    and the TensorDict); ``advanced indexing`` indexes the [E, T+1, H, W, 3] tensor directly.
    """
    stored = TensorDict.load_memmap(path / "episodes")
    frames = stored["pixels"].as_subclass(torch.Tensor).clone()  # [E, T+1, H, W, 3]
    actions = stored["action"].as_subclass(torch.Tensor).clone()  # [E, T, 4]
    poses = stored["object_pos"].as_subclass(torch.Tensor).clone()  # [E, T+1, N, 2]
    frame_rows, action_rows, pose_rows = (
        x.flatten(2).flatten(0, 1) for x in (frames, actions, poses)
    )
    stop = split_ranges(frames.shape[0], {"train": 0.8, "val": 0.1, "test": 0.1})["train"][1]

    def draw(generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        episode = torch.randint(stop, (BATCH,), generator=generator)
        step = torch.randint(steps, (BATCH,), generator=generator)
        times = torch.stack([torch.zeros_like(step), step, step + 1], dim=1)  # [B, 3]
        return episode, step, times

    def index_select(generator: torch.Generator) -> object:
        episode, step, times = draw(generator)
        rows = episode[:, None] * (steps + 1) + times
        return (
            frame_rows.index_select(0, rows.reshape(-1)),
            action_rows.index_select(0, episode * steps + step),
            pose_rows.index_select(0, rows[:, 1:].reshape(-1)),
        )

    def advanced_indexing(generator: torch.Generator) -> object:
        episode, step, times = draw(generator)
        return (
            frames[episode[:, None], times],
            actions[episode, step],
            poses[episode[:, None], times[:, 1:]],
        )

    return {
        "baseline: in-memory index_select": index_select,
        "reference: in-memory advanced indexing": advanced_indexing,
    }


def import_through_lerobot(path: Path, image_size: int) -> Path:
    """``path`` exported to LeRobot v3 without object state and imported beside it."""
    lerobot = export_lerobot(path, path.parent / "lerobot", include_object_state=False)
    settings = ImportSettings(image_size=image_size)
    return import_push_folder(
        plan_import(read_lerobot(lerobot).as_push_folder(), settings),
        path.parent,
        "imported",
        progress=False,
    )


def batches_per_second(sample: Callable[[torch.Generator], object], seconds: float) -> float:
    """Calls ``sample`` for about ``seconds`` and returns calls per second."""
    generator = torch.Generator().manual_seed(1)
    calls, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < seconds:
        for _ in range(50):
            sample(generator)
        calls += 50
    return calls / elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--image-size", type=int, default=64)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=1.0, help="per measurement")
    parser.add_argument("--lerobot", action="store_true", help="also time a LeRobot import")
    args = parser.parse_args()
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as root:
        path = Path(root) / "synthetic"
        start = time.perf_counter()
        write_synthetic_dataset(path, args.episodes, args.steps, args.image_size)
        size = sum(f.stat().st_size for f in path.rglob("*") if f.is_file())
        print(f"wrote {size / 2**20:.0f} MiB in {time.perf_counter() - start:.1f} s")
        data = load_dataset(path, "train")
        samplers = {
            **in_memory_baselines(path, args.steps),
            "sample(32)": lambda g: data.sample(BATCH, generator=g),
            "sample_sequences(8, 10)": lambda g: data.sample_sequences(8, 10, generator=g),
        }
        if args.lerobot:
            imported = load_dataset(import_through_lerobot(path, args.image_size), "train")
            samplers["imported: sample(32)"] = lambda g: imported.sample(BATCH, generator=g)
        for sample in samplers.values():  # warm up: pages into the cache
            batches_per_second(sample, 0.3)
        rates: dict[str, list[float]] = {name: [] for name in samplers}
        for _ in range(args.rounds):
            for name, sample in samplers.items():
                rates[name].append(batches_per_second(sample, args.seconds))
        medians = {name: statistics.median(values) for name, values in rates.items()}
        for name, rate in medians.items():
            print(f"{name}: {rate:.0f} batches/s")
        baseline = medians["baseline: in-memory index_select"]
        if args.lerobot:
            print(f"import ratio: {medians['imported: sample(32)'] / medians['sample(32)']:.2f}")
        print(f"ratio: {medians['sample(32)'] / baseline:.2f}")


if __name__ == "__main__":
    main()
