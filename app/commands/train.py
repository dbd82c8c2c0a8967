"""``lmm-studio train [all|decompressor|stepper|projector]``: train the learned motion matching networks.

Writes ``default.npz`` (decompressor, stepper, projector), ``compressor.npz`` and
``training_log.csv`` into ``--out``. The default recipe is the fast one measured to train the whole
pipeline on the shipped database in under 45 minutes on 2 CPU cores (see lmm/data/weights/README.md).
Shows one progress line per stage (redrawn in place on a terminal, a line a minute in a log file) and a
few summary lines at the end; the losses of every ``--log-every`` iterations are in ``training_log.csv``
(``--verbose`` prints them too). ``--json OUT`` (``-``: standard output) writes the whole summary. Ctrl+C or
SIGTERM ends it with one line saying where it stopped; weights files are replaced whole or not at all.
"""
from __future__ import annotations

import json
import os
import sys
import time

from app.cli import number_in

STAGES = ("all", "decompressor", "stepper", "projector")

# Accepted ranges. The recipe's longest stage is 11,000 iterations at ~20 per second on 2 cores:
# a million is half a day. A batch of 65,536 poses (668 floats each for the compressor) is ~175 MB per
# tensor. Learning rates beyond 1 only diverge. Seeds are numpy's (uint32).
MAX_ITERATIONS = 1_000_000
MAX_BATCH = 65_536
MAX_THREADS = 256
#: fewest frames --frames may keep: the stepper and decompressor train on windows of 20 frames
#: (Recipe.stepper_window) inside one range; far fewer left no window at all (numpy: "high <= 0")
MIN_FRAMES = 256


def thread_count(text: str) -> int:
    """``auto`` (0: :func:`lmm.offline.training_loop.auto_threads` or ``auto_workers`` decides) or
    1..MAX_THREADS (``--threads`` and ``--workers``)."""
    if text.strip().lower() == "auto":
        return 0
    return number_in(1, MAX_THREADS, integer=True)(text)


def add_arguments(p) -> None:
    p.add_argument("stage", nargs="?", default="all", choices=STAGES,
                   help="what to train (default: all; decompressor trains the compressor with it)")
    p.add_argument("--iterations", type=number_in(1, MAX_ITERATIONS, integer=True),
                   help=f"iterations per network, 1..{MAX_ITERATIONS} (default: the recipe's)")
    p.add_argument("--batch", type=number_in(1, MAX_BATCH, integer=True),
                   help=f"batch size per network, 1..{MAX_BATCH} (default: the recipe's)")
    p.add_argument("--lr", type=number_in(1e-9, 1.0), help="peak learning rate, 1e-9..1 (default: the recipe's)")
    p.add_argument("--out", default="lmm-weights", help="output folder (default: ./lmm-weights)")
    p.add_argument("--manifest", help="dataset manifest (default: the shipped LAFAN1 locomotion set)")
    p.add_argument("--seed", type=number_in(0, 2 ** 32 - 1, integer=True), default=1234,
                   help="random seed, 0..2^32-1 (default 1234)")
    p.add_argument("--threads", type=thread_count, default=0, metavar="auto|N",
                   help=f"torch threads, auto or 1..{MAX_THREADS} (default auto: 1 on 2 cores or fewer, else the "
                        "cores the load average leaves free less one; on a shared 2-core machine 2 threads "
                        "took 3-7x as long as 1, see the README)")
    p.add_argument("--workers", type=thread_count, default=0, metavar="auto|N",
                   help="training processes on the CPU, one thread each, the recipe's batch split among them "
                        "(DDP, gloo); default auto: 2 on a 2-core machine, else 1 (README, \"Training threads and "
                        "processes\")")
    p.add_argument("--json", dest="json_path", metavar="OUT",
                   help="write the summary (losses, times, paths) here as JSON; - prints it")
    p.add_argument("--frames", type=number_in(MIN_FRAMES, 2 ** 31, integer=True),
                   help=f"train on the first N database frames only (quick checks), at least {MIN_FRAMES}")
    p.add_argument("--log-every", type=number_in(1, MAX_ITERATIONS, integer=True), default=200,
                   help="a row of mean losses in training_log.csv every N iterations (default 200)")
    p.add_argument("--resume", action="store_true",
                   help="stepper/projector: continue from the networks in --out with a new schedule")
    p.add_argument("--device", default="auto",
                   help="auto (CUDA when present, else CPU), cpu, cuda or cuda:N; under torchrun each process "
                        "takes its local rank's GPU (see lmm/offline/distributed.py)")
    talk = p.add_mutually_exclusive_group()
    talk.add_argument("--quiet", action="store_true", help="no progress lines (the summary still prints)")
    talk.add_argument("--verbose", action="store_true",
                      help="print each training_log.csv row (every --log-every iterations) instead of the progress")


def main(args) -> int:
    from app.commands.extras import require
    if not require("train", "torch"):  # before the database: a missing extra fails at once
        return 2
    import numpy as np
    from pathlib import Path

    from lmm.data.build import load_or_build
    from lmm.features import build_features
    from lmm.offline.training import NETWORKS, Recipe, train_pipeline

    from lmm.offline.distributed import SPLIT_ENV, launch_workers, pick_device, setup, split_batch, teardown

    device = pick_device(args.device)  # a device not here fails now (DeviceError: one line), before the database
    from lmm.offline.training_loop import auto_threads, auto_workers

    workers = 1      # processes this command starts (under torchrun, or on a GPU: itself alone)
    if "WORLD_SIZE" not in os.environ and device.type == "cpu":
        workers = args.workers or (1 if args.threads else auto_workers())
    if workers > 1 and args.threads > 1:
        print(f"lmm-studio train: --workers {workers} runs one thread each; drop --threads {args.threads} "
              "or ask for --workers 1", file=sys.stderr)
        return 2
    from lmm.data.build import manifest_inputs
    from lmm.data.outputs import check_outputs
    from lmm.offline.training import COMPRESSOR_FILE, LOG_FILE, RUNTIME_FILE

    # a read-only or file --out, or one holding the manifest or a take, fails now, not after training
    json_out = None if args.json_path in (None, "-") else args.json_path
    # under torchrun only rank 0 writes the files, so only it holds their locks (the others check the paths);
    # a launcher of workers checks them for its rank 0, which locks them
    writer = os.environ.get("RANK", "0") == "0" and workers == 1
    check_outputs([("--out", Path(args.out) / name) for name in (RUNTIME_FILE, COMPRESSOR_FILE, LOG_FILE)]
                  + [("--json", json_out)], manifest_inputs(args.manifest), lock=writer)
    if writer:   # what a killed training left half-written there (its locks are ours now: no live writer)
        from lmm.data.leftovers import remove_stale
        remove_stale(args.out)
    db, _ = load_or_build(args.manifest)   # also a cache the workers below then read
    features = build_features(db)
    if workers > 1:
        if args.stage not in ("all", "decompressor"):   # what the stage starts from: its error here, once
            from lmm.offline.training import check_stage_inputs
            check_stage_inputs(db, features, Path(args.out))
        del db, features
        return launch_workers(workers, worker_argv(args))
    threads = args.threads or auto_threads()
    recipe = Recipe(seed=args.seed, threads=threads, log_every=args.log_every)
    stages = NETWORKS if args.stage == "all" else (args.stage,)
    for name in stages:
        s = recipe.stage(name)
        if args.iterations:
            s.iterations = args.iterations
        if args.batch:
            s.batch = args.batch
        if args.lr:
            s.lr = args.lr
    frames = np.arange(min(args.frames, db.n_frames)) if args.frames else None
    par = setup(args.device)
    shared = bool(os.environ.get(SPLIT_ENV)) and par.distributed   # started by launch_workers: the batch is shared
    if shared:
        for name in stages:
            recipe.stage(name).batch = split_batch(recipe.stage(name).batch, par.world)
    try:
        if par.is_main:
            where = f"{par.device}" + (f" x {par.world} processes (DDP)" if par.distributed else "")
            if shared:
                where += " sharing each batch"
            how = "auto" if not args.threads or shared else "--threads"
            print(f"training {', '.join(stages)} on {db.name} ({db.n_frames} frames, key {db.key[:16]}) on "
                  f"{where}, {threads} thread{'s' if threads > 1 else ''} ({how}) -> {args.out}", file=sys.stderr)
        t0 = time.perf_counter()
        # WeightsError / OSError: one line from app/cli.py
        summary = train_pipeline(db, features, stages, recipe, args.out, frames=frames, quiet=args.quiet,
                                 resume=args.resume, par=par, verbose=args.verbose)
        summary["command_wall_s"] = round(time.perf_counter() - t0, 1)
        summary["device"], summary["processes"] = str(par.device), par.world
        summary["threads"] = threads
        summary["batch_per_process"] = {name: recipe.stage(name).batch for name in stages}
        if par.is_main:
            print(summary_lines(summary))
            if args.json_path == "-":
                print(json.dumps(summary, indent=2))
            elif args.json_path:
                from lmm.data.jsonio import write_json
                write_json(args.json_path, summary)
    finally:
        teardown(par)
    return 0


def worker_argv(args) -> list[str]:
    """The arguments of one of :func:`lmm.offline.distributed.launch_workers`' processes: this command's,
    on the CPU, one thread."""
    argv = [args.stage, "--out", str(args.out), "--seed", str(args.seed), "--log-every", str(args.log_every),
            "--device", "cpu", "--threads", "1", "--workers", "1"]
    for flag, value in (("--iterations", args.iterations), ("--batch", args.batch), ("--lr", args.lr),
                        ("--manifest", args.manifest), ("--json", args.json_path), ("--frames", args.frames)):
        if value is not None:
            argv += [flag, str(value)]
    argv += [flag for flag, on in (("--resume", args.resume), ("--quiet", args.quiet), ("--verbose", args.verbose))
             if on]
    return argv


def how_many(summary: dict) -> str:
    """``2 processes x 1 thread`` or ``1 thread``."""
    threads = f"{summary['threads']} thread{'s' if summary['threads'] > 1 else ''}"
    n = summary.get("processes", 1)
    return f"{n} processes x {threads}" if n > 1 else threads


def summary_lines(summary: dict) -> str:
    """A few lines: per stage its loss from the first to the last logged row (one figure when a stage
    logged one row) and its time, then the files."""
    lines = []
    for name, last in summary["final_loss"].items():
        first = summary["first_loss"][name]   # the mean over the first --log-every iterations
        losses = f"{last:.4f}" if first == last else f"{first:.4f} -> {last:.4f}"
        lines.append(f"{name:<12} loss {losses} in "
                     f"{summary['wall_s'].get(name, summary['wall_s'].get(name + '_resumed', 0.0)):.1f} s")
    paths = summary["paths"]
    lines.append(f"wrote {paths['runtime']}, {paths['compressor']}, {paths['log']} "
                 f"({summary['command_wall_s']:.1f} s, {how_many(summary)})")
    return "\n".join(lines)
