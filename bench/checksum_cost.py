"""Checksum cost: hashing a committed chunk against collecting it, and verify time per frame.

Usage: MUJOCO_GL=egl python bench/checksum_cost.py [--episodes 200] [--chunk 16] [--raw-steps 240]

Writes a synthetic 64 px, 60-push dataset with the real ``EpisodeWriter`` (which records the
checksums), then times, warm in the page cache: the SHA-256 of one chunk of ``--chunk``
episodes (``episode_digests``, what each commit adds), the atomic rewrite of a progress record
holding the digests of 8,000 episodes (the paper scale's last and largest), and
``verify_dataset`` over the whole dataset, warm and after evicting its files from the page
cache (``posix_fadvise(DONTNEED)``, so the arrays are read from the disk). Collecting the chunk is estimated from one raw
``make_env`` env (blocks, top camera, 64 px) stepped before and after (median), which
1-worker collection matches (docs/data.md, collection speed). The last line is ``ratio: X`` =
checksum seconds per chunk (hash + record) over the seconds to collect that chunk.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import torch

from collect_throughput import ENV_CONFIG, raw_step_rate
from kinet_rl.atomic import atomic_write_json
from kinet_rl.data import verify_dataset
from kinet_rl.data.storage import episode_digests, open_episodes
from loader_throughput import write_synthetic_dataset

PAPER_EPISODES = 8000


def chunk_hash_seconds(path: Path, chunk: int) -> float:
    """Median seconds of ``episode_digests`` over each full chunk of the stored episodes."""
    storage = open_episodes(path)
    names = list(storage.keys())
    times = []
    for start in range(0, storage.shape[0] - chunk + 1, chunk):
        begin = time.perf_counter()
        episode_digests(storage, names, start, start + chunk)
        times.append(time.perf_counter() - begin)
    return statistics.median(times)


def record_seconds(path: Path) -> float:
    """Median seconds of writing a progress record with ``PAPER_EPISODES`` digests."""
    record = {"checksums": {"algorithm": "sha256", "episodes": ["0" * 64] * PAPER_EPISODES}}
    times = []
    for _ in range(5):
        begin = time.perf_counter()
        atomic_write_json(path / "record.json", record)
        times.append(time.perf_counter() - begin)
    return statistics.median(times)


def evict_from_page_cache(path: Path) -> None:
    """Drops the (clean, synced) pages of every file under ``path`` from the page cache."""
    for file in path.rglob("*"):
        if file.is_file():
            fd = os.open(file, os.O_RDONLY)
            try:
                os.fsync(fd)
                os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
            finally:
                os.close(fd)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=200, help="synthetic episodes")
    parser.add_argument("--chunk", type=int, default=16, help="episodes per commit")
    parser.add_argument("--raw-steps", type=int, default=240, help="steps of the raw env")
    args = parser.parse_args()
    torch.set_num_threads(1)
    steps, size = ENV_CONFIG["max_steps"], ENV_CONFIG["image_size"]
    raws = [raw_step_rate(args.raw_steps)]
    with tempfile.TemporaryDirectory() as root:
        path = Path(root) / "synthetic"
        write_synthetic_dataset(path, args.episodes, steps, size)
        hash_s = chunk_hash_seconds(path, args.chunk)
        write_s = record_seconds(Path(root))
        cold = []
        for _ in range(3):
            evict_from_page_cache(path)
            cold.append(verify_dataset(path))
        reports = [verify_dataset(path) for _ in range(3)]  # warm
    raws.append(raw_step_rate(args.raw_steps))
    raw = statistics.median(raws)
    collect_s = args.chunk * steps / raw
    verify_s = statistics.median(report.seconds for report in reports)
    cold_s = statistics.median(report.seconds for report in cold)
    frames = args.episodes * (steps + 1)
    assert all(report.verified for report in reports + cold)
    print(f"raw env: {raw:.1f} steps/s (median of {', '.join(f'{r:.1f}' for r in raws)})")
    print(f"collect one chunk of {args.chunk} episodes x {steps} pushes: {collect_s:.1f} s")
    print(f"hash one chunk ({size} px): {hash_s * 1e3:.1f} ms ({hash_s / collect_s:.2%})")
    print(
        f"progress record with {PAPER_EPISODES} digests: {write_s * 1e3:.1f} ms "
        f"({write_s / collect_s:.2%} of a chunk, the largest)"
    )
    print(
        f"verify_dataset: {verify_s:.2f} s for {frames} frames = "
        f"{verify_s / frames * 1e3:.3f} s per 1,000 frames ({size} px, page cache warm)"
    )
    print(
        f"verify_dataset from disk: {cold_s:.2f} s = {cold_s / frames * 1e3:.3f} s per 1,000 "
        "frames (files evicted from the page cache)"
    )
    print(f"ratio: {(hash_s + write_s) / collect_s:.4f}")


if __name__ == "__main__":
    main()
