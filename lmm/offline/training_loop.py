"""What the three training stages' loops share: the recipe (each stage's schedule), the optimiser with
its warm-up and cosine decay, one optimisation step, the seeding, the loss log (a progress line per stage
on the console, the CSV of every stage's terms, loss lines on request), the thread count a machine should
train with, and holding Ctrl+C and SIGTERM while a set of files is written.
"""
from __future__ import annotations

import csv
import io
import math
import os
import signal
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from lmm.progress import Progress


@dataclass
class StageSettings:
    iterations: int
    batch: int
    lr: float
    warmup: float = 0.02          # fraction of iterations with a linear lr ramp
    final_lr_fraction: float = 0.01  # cosine decay to lr * this
    weight_decay: float = 1e-3


@dataclass
class Recipe:
    """The training recipe. Defaults: measured to fit 20 minutes on a 2-core CPU machine with the default
    processes (16.6 min there, 2026-11-27; lmm/data/weights/README.md) within the quality limits
    (decompressor <= 2.0 cm mean joint error, projector agreement >= 0.8)."""
    decompressor: StageSettings = field(default_factory=lambda: StageSettings(1500, 512, 2e-3))
    stepper: StageSettings = field(default_factory=lambda: StageSettings(3500, 128, 2e-3))
    projector: StageSettings = field(default_factory=lambda: StageSettings(11000, 512, 2e-3))
    stepper_window: int = 20
    projector_noise: float = 0.5   # query noise level, x std of each feature (see noisy_queries)
    projector_neighbours: int = 16  # database neighbours per frame in the cell term (see train_projector)
    projector_margin: float = 0.1   # how far inside its nearest neighbour's cell a projection should land
    seed: int = 1234
    threads: int = 0               # torch threads; 0: auto_threads() on the machine that trains
    latent: int = 32
    hidden: int = 512
    log_every: int = 200

    def to_dict(self) -> dict:
        return asdict(self)

    def stage(self, name: str) -> StageSettings:
        return getattr(self, name)


def make_optimizer(params, s: StageSettings):
    opt = torch.optim.AdamW(params, lr=s.lr, weight_decay=s.weight_decay, amsgrad=True)
    warm = max(int(s.warmup * s.iterations), 1)

    def factor(i: int) -> float:
        if i < warm:
            return (i + 1) / warm
        t = min((i - warm) / max(s.iterations - warm, 1), 1.0)
        return s.final_lr_fraction + (1.0 - s.final_lr_fraction) * 0.5 * (1.0 + math.cos(math.pi * t))

    return opt, torch.optim.lr_scheduler.LambdaLR(opt, factor)


def usable_cores() -> int:
    """The cores this process may run on (its affinity, else the machine's)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def auto_threads(cores: int | None = None, load: float | None = None) -> int:
    """The torch thread count for this machine: 1 where there are 2 cores or fewer, else the cores the
    last minute's load average leaves free, less one (for the system), at least 1.

    Measured on a 2-core machine shared with other work (load 3-6): 30 decompressor iterations took
    7.2-8.7 s with 1 thread and 23-60 s with 2 (README, "Training threads and processes"); torch's threads
    spin waiting for each other when a core is taken by someone else, so more threads than free cores is far slower."""
    if cores is None:
        cores = usable_cores()
    if load is None:
        try:
            load = os.getloadavg()[0]
        except (AttributeError, OSError):
            load = 0.0
    if cores <= 2:
        return 1
    return max(1, min(cores - 1, int(cores - load) - 1))


def auto_workers(cores: int | None = None) -> int:
    """Training processes for a CPU run (``train --workers auto``): two single-threaded processes on a
    machine of two cores, else one (whose torch threads :func:`auto_threads` picks).

    Measured on this project's 2-core machine, three alternating rounds each (``bench/train_workers.py``; README,
    "Training threads and processes"): two processes sharing each batch against one process on one thread were
    1.16x (1.48x in an earlier round) for the decompressor, 1.11x for the projector and 1.04x (0.91x) for the
    stepper, whose batch of 128 is too small to share. Machines with more cores were not measured with several
    processes: there one process's threads share the work."""
    if cores is None:
        cores = usable_cores()
    return 2 if cores == 2 else 1


@contextmanager
def interrupts_held():
    """Ctrl+C (SIGINT) and SIGTERM wait until the block ends, then act as they would have: the files
    written inside (the compressor and the runtime weights, which belong together) are all written or
    none. Only the main thread receives signals; elsewhere the block runs as is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    hold = lambda signum, frame: caught.append(signum)  # noqa: E731
    previous = {sig: signal.signal(sig, hold) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if caught:
        signal.raise_signal(caught[0])   # now handled by the handler that was there before


#: seconds between progress lines when the console is not a terminal (a log file): the full recipe's
#: 36 minutes on one thread make about as many lines, where the terminal's 0.2 s would make thousands
PIPED_PROGRESS_S = 60.0


def console_progress(total: int, label: str, stream=None, enabled: bool = True) -> Progress:
    """A progress line for a phase of training: redrawn in place on a terminal, a line every
    :data:`PIPED_PROGRESS_S` otherwise (and at the end)."""
    stream = stream if stream is not None else sys.stderr
    tty = bool(getattr(stream, "isatty", lambda: False)())
    return Progress(total, label=label, stream=stream, enabled=enabled, min_interval_s=0.2 if tty else PIPED_PROGRESS_S)


class LossLog:
    """Collects per-iteration losses, writes a CSV row of their means every ``log_every`` iterations and
    shows a progress line (redrawn in place on a terminal, one line a minute otherwise). ``verbose``
    prints each CSV row as a loss line instead of the progress line; ``quiet`` prints nothing.
    ``LossLog.latest`` is the last one started (where an interrupted training stopped)."""

    latest: "LossLog | None" = None

    def __init__(self, network: str, total: int, log_every: int, csv_path=None, stream=None, quiet=False,
                 verbose=False):
        self.network = network
        self.log_every = max(int(log_every), 1)
        self.stream = stream if stream is not None else sys.stderr
        self.verbose = verbose and not quiet
        self.rows: list[dict] = []
        self._acc: dict[str, float] = {}
        self._n = 0
        self.csv_path = Path(csv_path) if csv_path else None
        self.start = time.perf_counter()
        self.progress = console_progress(total, network, self.stream, enabled=not (quiet or self.verbose))
        LossLog.latest = self

    def add(self, iteration: int, lr: float, terms: dict[str, float]) -> None:
        for k, v in terms.items():
            self._acc[k] = self._acc.get(k, 0.0) + v
        self._n += 1
        total = terms["loss"]
        self.progress.update(1, postfix=f"loss {total:.4f}")
        if (iteration + 1) % self.log_every == 0 or iteration + 1 == self.progress.total:
            row = {"network": self.network, "iteration": iteration + 1,
                   "elapsed_s": round(time.perf_counter() - self.start, 2), "lr": lr}
            row.update({k: v / self._n for k, v in self._acc.items()})
            self.rows.append(row)
            self._acc, self._n = {}, 0
            if self.verbose:
                terms_txt = " ".join(f"{k}={v:.4g}" for k, v in row.items() if k not in ("network", "iteration", "elapsed_s", "lr", "loss"))
                self.stream.write(f"[{self.network}] it {row['iteration']} loss {row['loss']:.5f} lr {lr:.2e} "
                                  f"{row['elapsed_s']:.0f}s | {terms_txt}\n")
                self.stream.flush()
            if self.csv_path:
                with interrupts_held():
                    self._write_csv()

    def _write_csv(self) -> None:
        keys: list[str] = []
        for r in self.rows:
            keys += [k for k in r if k not in keys]
        existing = []
        if self.csv_path.exists():
            with open(self.csv_path, newline="") as f:
                existing = [r for r in csv.DictReader(f) if r.get("network") != self.network]
            for r in existing:
                keys += [k for k in r if k not in keys]
        from lmm.data.atomic import write_bytes_atomic

        text = io.StringIO(newline="")
        w = csv.DictWriter(text, fieldnames=keys)
        w.writeheader()
        for r in existing + self.rows:
            w.writerow(r)
        # a temporary named after this process, which the next train removes if a kill left it
        write_bytes_atomic(self.csv_path, text.getvalue().encode("utf-8"))

    def close(self) -> None:
        self.progress.close()

    @property
    def first_loss(self) -> float:
        return float(self.rows[0]["loss"]) if self.rows else float("nan")

    @property
    def last_loss(self) -> float:
        return float(self.rows[-1]["loss"]) if self.rows else float("nan")


def seed_all(seed: int) -> np.random.Generator:
    """Seed torch and return a numpy generator of the same seed (the batches' frame draws)."""
    torch.manual_seed(seed)
    return np.random.default_rng(seed)


def optimise_step(loss, terms: dict, opt, sched, log, it: int) -> None:
    """One optimiser and schedule step, then the loss and its terms into the log."""
    opt.zero_grad(set_to_none=True)
    loss.backward()
    opt.step()
    sched.step()
    log.add(it, sched.get_last_lr()[0], {"loss": float(loss.detach()), **{k: float(v.detach()) for k, v in terms.items()}})
