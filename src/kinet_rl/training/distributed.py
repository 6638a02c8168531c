"""Data-parallel training under ``torchrun`` (gloo on CPU, nccl on GPU)."""

from __future__ import annotations

import os
from dataclasses import dataclass

import torch
import torch.distributed as dist
from torch import nn

from kinet_rl.devices import resolve_device


@dataclass(frozen=True)
class DistContext:
    """Where this process sits in a (possibly single-process) data-parallel run."""

    rank: int = 0
    world_size: int = 1
    device: torch.device = torch.device("cpu")

    @property
    def is_main(self) -> bool:
        return self.rank == 0


def init_distributed(device: str = "auto") -> DistContext:
    """Joins the ``torchrun`` process group if one is set up, else runs as a single process.

    Args:
        device: ``"auto"`` (CUDA when available), ``"cpu"`` or ``"cuda"``.
    """
    device = str(resolve_device(device))
    world_size = int(os.environ.get("WORLD_SIZE", "1"))
    if world_size == 1:
        return DistContext(device=torch.device(device))
    rank = int(os.environ["RANK"])
    local_rank = int(os.environ.get("LOCAL_RANK", rank))
    if device == "cuda":
        torch.cuda.set_device(local_rank)
        dev = torch.device("cuda", local_rank)
    else:
        dev = torch.device("cpu")
    if not dist.is_initialized():
        dist.init_process_group(backend="nccl" if dev.type == "cuda" else "gloo")
    return DistContext(rank=rank, world_size=world_size, device=dev)


def process_rank() -> int:
    """This process's rank under ``torchrun`` (0 outside it), readable before joining the group."""
    return int(os.environ.get("RANK", "0"))


def wrap_data_parallel(module: nn.Module, ctx: DistContext) -> nn.Module:
    """Wraps ``module`` in DistributedDataParallel when running with several processes."""
    if ctx.world_size == 1:
        return module
    device_ids = [ctx.device.index] if ctx.device.type == "cuda" else None
    # A static graph tolerates parameters that a loss never uses (e.g. an ablation's) and a
    # TensorDict output, which find_unused_parameters cannot traverse.
    return nn.parallel.DistributedDataParallel(module, device_ids=device_ids, static_graph=True)


def mean_across_processes(value: float, ctx: DistContext) -> float:
    """Averages a scalar over all processes (identity in a single process)."""
    if ctx.world_size == 1:
        return value
    tensor = torch.tensor([value], dtype=torch.float64, device=ctx.device)
    dist.all_reduce(tensor)
    return tensor.item() / ctx.world_size
