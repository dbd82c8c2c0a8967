"""Cost of ``lmm-studio compare``'s DTW (numpy, row-wise closed form) on a LAFAN1 take against itself
time-warped by 1.25x, for several lengths. Prints milliseconds (median of 3) per comparison.

    python bench/compare_dtw.py [--take FILE.bvh]

Why numpy and not dtaidistance: the cost of a frame pair is the mean geodesic angle over joints of
q_a^-1 q_b, not a Euclidean distance between per-frame vectors (the only cost dtaidistance's
multivariate DTW takes), and the banded numpy DTW below is fast enough for takes of minutes.
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from lmm.compare import compare_motions, motion_from_animation
from lmm.data import bvh


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--take", default=None, help="a LAFAN1 take (default: the shipped manifest's first clip)")
    args = p.parse_args()
    if args.take is None:
        from lmm import DEFAULT_MANIFEST
        from lmm.data.manifest import load_manifest
        args.take = load_manifest(DEFAULT_MANIFEST).clips[0].file
    anim = bvh.load(args.take)
    for seconds in (10, 30, 60, 120):
        n = min(int(seconds * 30), anim.n_frames)
        a = motion_from_animation(anim, "A", frames=(0, n), hips_forward_axis=(0.0, 1.0, 0.0))
        idx = np.minimum(np.rint(np.arange(int(n * 1.25)) / 1.25).astype(int), n - 1)
        b = type(a)("B", a.joints, a.rotations[idx], a.world_cm[idx], a.local_cm[idx], a.fps)
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            r = compare_motions(a, b)
            times.append((time.perf_counter() - t0) * 1e3)
        print(f"{n} x {len(idx)} frames ({seconds} s at 30 fps), window {r['window']}: "
              f"{statistics.median(times):.0f} ms, rotation error {r['rotation_error_rad']:.2e} rad")


if __name__ == "__main__":
    main()
