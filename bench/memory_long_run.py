"""Resident memory of a long headless run: RSS after the first simulated minute and at the end.

    PYTHONPATH=. python bench/memory_long_run.py [--minutes 10] [--controller mm|lmm] [--input builtin:random:1]

Runs as fast as possible (not paced to the wall clock) through :func:`lmm.runner.run_headless`, with
the metrics of ``lmm-studio run`` and, with ``--record DIR``, its recording streams. Prints RSS (from
/proc/self/status) at 1 minute and at the end and the growth between them; the issue's target is a
growth under 1 MB over a 10-minute run.
"""
from __future__ import annotations

import argparse
import gc
import json
import tempfile
import time
from pathlib import Path


def rss_bytes() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise RuntimeError("no VmRSS in /proc/self/status")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--controller", default="mm", choices=("mm", "lmm"))
    ap.add_argument("--input", default="builtin:random:1")
    ap.add_argument("--record", metavar="DIR", help="also stream the recording (BVH + input CSV) into DIR")
    args = ap.parse_args()

    from lmm.data.build import load_or_build
    from lmm.data.inputs import InputCsvWriter, open_input
    from lmm.data.recording import BVHRecorder
    from lmm.factory import make_controller
    from lmm.features import build_features
    from lmm.runner import run_headless
    from lmm.tuning import Tuning

    seconds = args.minutes * 60.0
    db, _ = load_or_build()
    features = build_features(db)
    controller = make_controller(args.controller, db, features, Tuning(), None)
    source = open_input(args.input, seconds)
    fps = 60.0
    samples = {}
    tick = [0]

    def on_step(pose, snap):
        tick[0] += 1
        if tick[0] in (int(60 * fps), int(seconds * fps)):
            gc.collect()
            samples[tick[0] / fps] = rss_bytes()

    recorder = writer = None
    folder = None
    if args.record:
        folder = Path(args.record)
        folder.mkdir(parents=True, exist_ok=True)
        recorder = BVHRecorder(folder / "long.bvh", db, fps=fps)
        writer = InputCsvWriter(folder / "long.input.csv")
    t0 = time.perf_counter()
    metrics = run_headless(controller, source, seconds, dt=1.0 / fps, recorder=recorder, input_writer=writer,
                           on_step=on_step)
    wall = time.perf_counter() - t0
    if recorder is not None:
        recorder.close()
        writer.close()
    (first, a), (last, b) = sorted(samples.items())[0], sorted(samples.items())[-1]
    report = {"controller": args.controller, "input": args.input, "simulated_s": seconds, "ticks": metrics["ticks"],
              "wall_s": round(wall, 1), f"rss_mb_at_{first:g}s": round(a / 2**20, 2),
              f"rss_mb_at_{last:g}s": round(b / 2**20, 2), "growth_mb": round((b - a) / 2**20, 3),
              "growth_bytes_per_tick": round((b - a) / max(metrics["ticks"] - 60 * fps, 1), 2),
              "step_us_median": round(metrics["step_us_median"], 1)}
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
