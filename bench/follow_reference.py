#!/usr/bin/env python
"""Cost of following a reference (lmm.follow), per tick and per controller: the pose's compared rotations
(:func:`lmm.follow.pose_rotations`) plus the aligned frame search and error (:class:`lmm.follow.FrameTracker`),
the work :meth:`app.session.Session.follow_series` adds to every tick; and the one-off preparation
(:func:`lmm.follow.follow_take`: root path, derived input, aligned take) of a held-out walk and of a whole take.

    python bench/follow_reference.py [--ticks 2000]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from lmm import DEFAULT_MANIFEST  # noqa: E402
from lmm.data import bvh  # noqa: E402
from lmm.data.manifest import load_manifest  # noqa: E402
from lmm.follow import FrameTracker, follow_take, pose_rotations  # noqa: E402

TAKE = ROOT / "lmm" / "data" / "lafan1" / "obstacles3_subject3.bvh.gz"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ticks", type=int, default=2000)
    args = ap.parse_args()
    manifest = load_manifest(DEFAULT_MANIFEST)
    anim = bvh.load(TAKE)
    names = ["Simulation", *anim.names]
    t0 = time.perf_counter()
    take = follow_take(anim, manifest, names, path=TAKE.name, frames=(3526, 3781))
    t1 = time.perf_counter()
    whole = follow_take(anim, manifest, names, path=TAKE.name)
    t2 = time.perf_counter()
    print(f"prepare: {take.duration_s:.1f} s range {1e3 * (t1 - t0):.0f} ms; whole take "
          f"({whole.duration_s:.0f} s) {1e3 * (t2 - t1):.0f} ms")
    # poses of the database skeleton (float32 like a controller's), from the take a little off its timing
    g_rot, _ = anim.global_transforms()
    local = anim.local_rotations()
    tracker = FrameTracker(take)
    per_tick = []
    for i in range(args.ticks):
        f = 3526 + min(int(i / 2 + 3 * np.sin(i / 20)), 254)
        lr = np.concatenate([[[1.0, 0, 0, 0]], local[f]]).astype(np.float32)
        gr = np.concatenate([[[1.0, 0, 0, 0]], g_rot[f]]).astype(np.float32)
        s = time.perf_counter()
        rot = pose_rotations(lr, gr, names, take.hips_forward_axis)
        tracker.track((i % 500) / 60.0, rot)
        per_tick.append(time.perf_counter() - s)
        if i % 500 == 499:
            tracker.reset()
    us = np.array(per_tick) * 1e6
    print(f"per tick and controller ({len(names) - 1} joints, window {tracker.window} frames each side): "
          f"median {statistics.median(us):.0f} us, p95 {np.percentile(us, 95):.0f} us over {args.ticks} ticks")


if __name__ == "__main__":
    main()
