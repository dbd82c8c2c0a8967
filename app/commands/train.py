"""``lmm-studio train [all|decompressor|stepper|projector]``: train the learned motion matching networks.

Writes ``default.npz`` (decompressor, stepper, projector), ``compressor.npz`` and
``training_log.csv`` into ``--out``. The default recipe is the fast one measured to train the whole
pipeline on the shipped database in under 45 minutes on 2 CPU cores (see lmm/data/weights/README.md).
"""
from __future__ import annotations

import json
import sys
import time

from app.cli import number_in

STAGES = ("all", "decompressor", "stepper", "projector")

# Accepted ranges. The recipe's longest stage is 24,000 iterations at ~20-40 per second on 2 cores:
# a million is half a day. A batch of 65,536 poses (668 floats each for the compressor) is ~175 MB per
# tensor. Learning rates beyond 1 only diverge. Seeds are numpy's (uint32).
MAX_ITERATIONS = 1_000_000
MAX_BATCH = 65_536
MAX_THREADS = 256
#: fewest frames --frames may keep: the stepper and decompressor train on windows of 20 frames
#: (Recipe.stepper_window) inside one range; far fewer left no window at all (numpy: "high <= 0")
MIN_FRAMES = 256


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
    p.add_argument("--threads", type=number_in(1, MAX_THREADS, integer=True), default=2,
                   help="torch threads (default 2)")
    p.add_argument("--frames", type=number_in(MIN_FRAMES, 2 ** 31, integer=True),
                   help=f"train on the first N database frames only (quick checks), at least {MIN_FRAMES}")
    p.add_argument("--log-every", type=number_in(1, MAX_ITERATIONS, integer=True), default=200,
                   help="print a loss line every N iterations")
    p.add_argument("--resume", action="store_true",
                   help="stepper/projector: continue from the networks in --out with a new schedule")
    p.add_argument("--device", default="auto",
                   help="auto (CUDA when present, else CPU), cpu, cuda or cuda:N; under torchrun each process "
                        "takes its local rank's GPU (see lmm/offline/distributed.py)")
    p.add_argument("--quiet", action="store_true", help="no progress bar or loss lines")


def main(args) -> int:
    from app.commands.extras import require
    if not require("train", "torch"):  # before the database: a missing extra fails at once
        return 2
    import numpy as np
    from pathlib import Path

    from lmm.data.build import load_or_build
    from lmm.features import build_features
    from lmm.offline.training import NETWORKS, Recipe, train_pipeline

    from lmm.offline.distributed import pick_device, setup, teardown

    pick_device(args.device)  # a device not here fails now (DeviceError: one line), before the database
    from lmm.data.build import manifest_inputs
    from lmm.data.outputs import check_outputs
    from lmm.offline.training import COMPRESSOR_FILE, LOG_FILE, RUNTIME_FILE

    # a read-only or file --out, or one holding the manifest or a take, fails now, not after training
    check_outputs([("--out", Path(args.out) / name) for name in (RUNTIME_FILE, COMPRESSOR_FILE, LOG_FILE)],
                  manifest_inputs(args.manifest))
    db, _ = load_or_build(args.manifest)
    features = build_features(db)
    recipe = Recipe(seed=args.seed, threads=args.threads, log_every=args.log_every)
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
    try:
        if par.is_main:
            where = f"{par.device}" + (f" x {par.world} processes (DDP)" if par.distributed else "")
            print(f"training {', '.join(stages)} on {db.name} ({db.n_frames} frames, key {db.key[:16]}) on "
                  f"{where} -> {args.out}", file=sys.stderr)
        t0 = time.perf_counter()
        summary = train_pipeline(db, features, stages, recipe, args.out, frames=frames, quiet=args.quiet,
                                 resume=args.resume, par=par)  # WeightsError / OSError: one line from app/cli.py
        summary["command_wall_s"] = round(time.perf_counter() - t0, 1)
        summary["device"], summary["processes"] = str(par.device), par.world
        if par.is_main:
            print(json.dumps(summary, indent=2))
    finally:
        teardown(par)
    return 0
