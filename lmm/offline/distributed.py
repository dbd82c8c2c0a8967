"""Where training runs: one device (``--device auto|cpu|cuda|cuda:N``) or several processes started by
``torchrun``, each with its own device, their gradients averaged by DistributedDataParallel.

    lmm-studio train --device cuda                      # one GPU
    torchrun --nproc_per_node 4 -m app.cli train        # four GPUs on one machine (one process each)
    torchrun --nproc_per_node 2 -m app.cli train --device cpu   # two CPU processes (gloo), a smoke test

Under torchrun (``WORLD_SIZE`` > 1 in the environment) each process trains on its own batches (the
recipe's batch per process, so the global batch is ``WORLD_SIZE`` times it, drawn with a seed per rank),
DDP keeps the weights identical, and only rank 0 logs and writes files. The backend is NCCL on CUDA and
gloo on CPU. A single process keeps exactly the sampling and seeds of a plain run.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import torch

from lmm.errors import InputError


class DeviceError(InputError):
    """A device that cannot be used (no CUDA, a GPU index past the last one)."""


def pick_device(name: str = "auto", local_rank: int = 0) -> torch.device:
    """``auto``: CUDA when present (the process's ``local_rank`` GPU), else the CPU; ``cuda`` without
    an index also takes the local rank's GPU. Raises :class:`DeviceError` for a device not here."""
    name = (name or "auto").strip().lower()
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cpu":
        return torch.device("cpu")
    if name == "cuda" or name.startswith("cuda:"):
        if not torch.cuda.is_available():
            raise DeviceError(f"--device {name}: CUDA is not available here (torch {torch.__version__}); "
                              "use --device cpu")
        index = local_rank if name == "cuda" else name.split(":", 1)[1]
        try:
            index = int(index)
        except ValueError:
            raise DeviceError(f"--device {name}: expected cuda:N with a GPU number") from None
        if not 0 <= index < torch.cuda.device_count():
            raise DeviceError(f"--device {name}: GPU {index} not found ({torch.cuda.device_count()} here)")
        return torch.device("cuda", index)
    raise DeviceError(f"--device {name}: expected auto, cpu, cuda or cuda:N")


@dataclass
class Parallel:
    """One training process: its device, its rank among ``world`` processes."""
    device: torch.device
    rank: int = 0
    world: int = 1

    @property
    def distributed(self) -> bool:
        return self.world > 1

    @property
    def is_main(self) -> bool:
        return self.rank == 0

    def seed(self, seed: int) -> int:
        """A rank's sampling seed: rank 0 keeps ``seed`` (a single process samples as before)."""
        return int(seed) + 7919 * self.rank

    def wrap(self, module: torch.nn.Module) -> torch.nn.Module:
        """``module`` on this device; under torchrun wrapped in DistributedDataParallel (call the
        wrapper in the loop, save ``module`` itself)."""
        module.to(self.device)
        if not self.distributed:
            return module
        from torch.nn.parallel import DistributedDataParallel

        ids = [self.device.index] if self.device.type == "cuda" else None
        # static_graph: the stepper calls its network W times before one backward
        return DistributedDataParallel(module, device_ids=ids, static_graph=True)

    def barrier(self) -> None:
        if self.distributed:
            torch.distributed.barrier()


def setup(device: str = "auto") -> Parallel:
    """The current process's :class:`Parallel`: started by torchrun (``WORLD_SIZE`` > 1) it joins the
    process group (NCCL on CUDA, gloo on CPU), else a single process on ``device``."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return Parallel(pick_device(device))
    rank = int(os.environ.get("RANK", "0"))
    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    dev = pick_device(device, local_rank)
    if dev.type == "cuda":
        torch.cuda.set_device(dev)
    if not torch.distributed.is_initialized():
        torch.distributed.init_process_group(backend="nccl" if dev.type == "cuda" else "gloo")
    return Parallel(dev, rank, world)


def teardown(par: Parallel) -> None:
    if par.distributed and torch.distributed.is_initialized():
        torch.distributed.destroy_process_group()
