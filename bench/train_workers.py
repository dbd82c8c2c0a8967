#!/usr/bin/env python
"""How ``lmm-studio train`` should use this machine: alternating short trainings of each stage as one
process on one thread, one process on two threads, and two single-threaded processes sharing each batch
(``--workers 2``), the stage's own wall time (``wall_s`` of ``--json``, start-up and data preparation
excluded) per run and the median of each way. ``auto_workers`` and ``auto_threads``
(lmm/offline/training_loop.py) were chosen from this on the 2-core development machine.

    python bench/train_workers.py [--rounds 3] [--stages decompressor:60,stepper:100,projector:400]
                                  [--ways p1t1,p1t2,p2t1] [--json out.json]

The projector's figure includes its neighbour table (about 27 s on the default data, computed by each
process in full); the per-iteration rate is (projector - table) / iterations.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WAYS = {"p1t1": ["--workers", "1", "--threads", "1"], "p1t2": ["--workers", "1", "--threads", "2"],
        "p2t1": ["--workers", "2"]}


def one(stage: str, iterations: int, way: str, out: Path) -> dict:
    summary = out / f"{way}.json"
    cmd = [sys.executable, "-m", "app.cli", "train", stage, "--iterations", str(iterations), "--quiet",
           "--device", "cpu", "--out", str(out / way), "--json", str(summary), *WAYS[way]]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed: {done.stderr.strip().splitlines()[-1:]}")
    s = json.loads(summary.read_text())
    return {"wall_s": s["wall_s"][stage], "final_loss": s["final_loss"][stage], "processes": s["processes"],
            "threads": s["threads"]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--stages", default="decompressor:60,stepper:100,projector:400")
    ap.add_argument("--ways", default="p1t1,p1t2,p2t1")
    ap.add_argument("--json", dest="json_path")
    args = ap.parse_args()
    ways = args.ways.split(",")
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for spec in args.stages.split(","):
            stage, iterations = spec.split(":")
            runs = {w: [] for w in ways}
            for r in range(args.rounds):
                for w in ways:                       # alternating: each round runs every way once
                    res = one(stage, int(iterations), w, Path(tmp))
                    runs[w].append(res)
                    print(f"{stage:<12} round {r + 1} {w}: {res['wall_s']:.1f} s (loss {res['final_loss']:.4f})",
                          flush=True)
            results[stage] = {"iterations": int(iterations), "runs": runs,
                              "median_s": {w: statistics.median(x["wall_s"] for x in runs[w]) for w in ways}}
            med = results[stage]["median_s"]
            base = med[ways[0]]
            print(f"{stage:<12} medians: " + ", ".join(f"{w} {med[w]:.1f} s ({base / med[w]:.2f}x {ways[0]})"
                                                      for w in ways), flush=True)
    info = {"cpus": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
            "load_average": os.getloadavg()[0] if hasattr(os, "getloadavg") else None, "stages": results}
    if args.json_path:
        Path(args.json_path).write_text(json.dumps(info, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
