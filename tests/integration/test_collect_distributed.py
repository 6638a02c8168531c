"""The torch.distributed backend (TorchRL's DistributedCollector) gives the local dataset (slow).

Two collector nodes are started on this machine (``launcher="mp"``, gloo over TCP on localhost),
which exercises the same transport as nodes on other machines.
"""

from __future__ import annotations

import functools
import socket
from pathlib import Path

import pytest
from tensordict import TensorDict

from fake_push_env import make_fake_env
from kinet_rl.data import collect_dataset, load_dataset
from kinet_rl.data.storage import EPISODES_DIR

pytestmark = pytest.mark.slow

ENV_CONFIG = {"task": "fake", "camera": "top", "image_size": 8}


def free_port_pair() -> int:
    """A free TCP port p (DistributedCollector also binds p + 1, retrying elsewhere if taken)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def collect(root: Path, **kwargs) -> Path:
    env_fn = functools.partial(make_fake_env, image_size=8, max_steps=4, unstable_prob=0.1)
    return collect_dataset(
        env_fn,
        ENV_CONFIG,
        root=root,
        name="ds",
        num_episodes=8,
        seed=5,
        chunk_episodes=3,
        progress=False,
        **kwargs,
    )


@pytest.mark.timeout(120)
def test_distributed_backend_gives_the_local_dataset(tmp_path: Path) -> None:
    local = collect(tmp_path / "local", num_workers=1)
    distributed = collect(
        tmp_path / "distributed",
        num_workers=2,
        backend="distributed",
        distributed={"launcher": "mp", "tcp_port": free_port_pair()},
    )
    stored_local = TensorDict.load_memmap(local / EPISODES_DIR)
    stored_distributed = TensorDict.load_memmap(distributed / EPISODES_DIR)
    assert (stored_distributed == stored_local).all()
    metadata = load_dataset(distributed).metadata
    assert metadata["backend"] == "distributed" and metadata["num_workers"] == 2
    assert metadata["discarded_unstable"] == load_dataset(local).metadata["discarded_unstable"] > 0
