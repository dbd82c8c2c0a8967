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


#: set by :func:`launch_workers` in the processes it starts: the recipe's batch is split among them, so the
#: global batch stays the recipe's (torchrun's processes each train the whole batch, see the module doc)
SPLIT_ENV = "LMM_TRAIN_SPLIT_BATCH"


def split_batch(batch: int, world: int) -> int:
    """One process's share of a ``batch`` split among ``world`` processes (at least 1)."""
    return max(1, -(-int(batch) // max(int(world), 1)))


def _free_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _die_with_parent() -> None:   # in the child, before exec: a killed launcher takes its workers with it
    import ctypes
    import signal
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))   # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def launch_workers(workers: int, argv: list[str], stream=None) -> int:
    """Run ``lmm-studio train ARGV`` as ``workers`` single-threaded CPU processes on this machine whose
    gradients DistributedDataParallel averages (gloo), the recipe's batch split among them; rank 0 logs and
    writes the files. Ctrl+C and SIGTERM reach every worker once; a worker that fails stops the others.
    Returns the exit status: rank 0's, or the first failing worker's."""
    import signal
    import subprocess
    import sys
    import tempfile

    stream = stream if stream is not None else sys.stderr
    env = {**os.environ, "MASTER_ADDR": "127.0.0.1", "MASTER_PORT": str(_free_port()),
           "WORLD_SIZE": str(workers), "LOCAL_WORLD_SIZE": str(workers), "OMP_NUM_THREADS": "1", SPLIT_ENV: "1"}
    procs, errs = [], []
    for rank in range(workers):
        err = None if rank == 0 else tempfile.TemporaryFile()   # the others' lines only if they fail alone
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "app.cli", "train", *argv],
            env={**env, "RANK": str(rank), "LOCAL_RANK": str(rank)}, start_new_session=True,
            stdout=None if rank == 0 else subprocess.DEVNULL, stderr=err, preexec_fn=_die_with_parent))
        errs.append(err)

    def forward(signum, _frame):
        for p in procs:
            if p.poll() is None:
                p.send_signal(signum)

    import threading
    main = threading.current_thread() is threading.main_thread()   # only it may set handlers
    old = {s: signal.signal(s, forward) for s in (signal.SIGINT, signal.SIGTERM)} if main else {}
    try:
        codes = _wait_all(procs)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    bad = [(r, c) for r, c in enumerate(codes) if c != 0]
    if codes[0] == 0 and bad:          # rank 0 finished but another did not: say why, once
        rank = bad[0][0]
        errs[rank].seek(0)
        text = errs[rank].read().decode("utf-8", "replace").strip()
        stream.write((text.splitlines()[-1] if text else f"training worker {rank} failed") + "\n")
    for f in errs[1:]:
        f.close()
    return codes[0] if codes[0] != 0 or not bad else bad[0][1]


def _wait_all(procs) -> list[int]:
    """Wait for every process; once one fails, the others are stopped (DDP would wait for it forever)."""
    import time

    while True:
        codes = [p.poll() for p in procs]
        if all(c is not None for c in codes):
            return codes
        if any(c not in (None, 0) for c in codes):
            for p in procs:
                if p.poll() is None:
                    p.terminate()
            deadline = time.monotonic() + 30
            for p in procs:
                try:
                    p.wait(max(deadline - time.monotonic(), 0.1))
                except Exception:   # subprocess.TimeoutExpired
                    p.kill()
            return [p.wait() for p in procs]
        time.sleep(0.2)
