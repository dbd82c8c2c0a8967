#!/usr/bin/env python
"""The stable-PD ragdoll (lmm.physics.ragdoll) tracking MM and LMM output, headless.

For each controller (MM; LMM when its networks load) and each residual setting (root residual force on and
off), runs the controller for ``--seconds`` on ``--input`` (default 10 s of builtin:circle) and has a fresh
ragdoll track every tick. Prints the mean and largest joint position error (cm), the falls (a fallen ragdoll
is put back on the tracked pose after 1 s), the root residual force (fraction of body weight, mean and
median), the foot contact fractions and the wall time of the tracking simulation per 60 Hz tick (median of
the ticks, the controller's own time excluded).

    python bench/ragdoll_tracking.py [--seconds 10] [--input builtin:circle] [--substeps 8] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def track(controller, source, seconds: float, ragdoll) -> tuple[list, list]:
    from lmm.runner import run_headless

    ticks, times = [], []

    def on_step(pose, snap):
        t0 = time.perf_counter()
        ticks.append(ragdoll.step(pose.global_positions, pose.global_rotations))
        times.append(time.perf_counter() - t0)

    run_headless(controller, source, seconds, on_step=on_step)
    return ticks, times


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--input", default="builtin:circle")
    p.add_argument("--substeps", type=int, default=8)
    p.add_argument("--json", help="write the numbers here")
    args = p.parse_args(argv)

    from lmm.data.build import load_or_build
    from lmm.data.inputs import open_input
    from lmm.factory import make_controllers
    from lmm.features import build_features
    from lmm.physics.ragdoll import Ragdoll, RagdollSettings, body_for_database, summarize
    from lmm.tuning import Tuning

    db, _ = load_or_build()
    features = build_features(db)
    controllers, problems = make_controllers(db, features, Tuning())
    for problem, _ in problems:
        print(f"note: {problem}")
    body = body_for_database(db)
    print(f"body: {len(body.joints)} bodies, {body.nv} dofs, {body.total_mass:g} kg, height {body.height_m:.2f} m; "
          f"{args.substeps} substeps per tick; {args.seconds:g} s of {args.input}")
    out = {}
    print(f"{'controller':10s} {'residual':8s} {'err cm':>7s} {'max cm':>7s} {'falls':>5s} {'res BW':>7s} "
          f"{'med BW':>7s} {'L cont':>6s} {'R cont':>6s} {'ms/tick':>7s}")
    for name, controller in controllers.items():
        for residual in (True, False):
            ragdoll = Ragdoll(body, settings=RagdollSettings(residual=residual, substeps=args.substeps))
            ticks, times = track(controller, open_input(args.input, args.seconds), args.seconds, ragdoll)
            s = summarize(ticks, float(np.median(times)))
            print(f"{name:10s} {'on' if residual else 'off':8s} {s.mean_error_cm:7.2f} {s.max_error_cm:7.2f} "
                  f"{s.falls:5d} {s.mean_residual_bw:7.3f} {s.median_residual_bw:7.3f} "
                  f"{s.contact_fraction[0]:6.2f} {s.contact_fraction[1]:6.2f} {s.ms_per_tick:7.3f}")
            out[f"{name}_residual_{'on' if residual else 'off'}"] = {
                "mean_error_cm": s.mean_error_cm, "max_error_cm": s.max_error_cm, "falls": s.falls,
                "mean_residual_bw": s.mean_residual_bw, "median_residual_bw": s.median_residual_bw,
                "contact_fraction": [float(x) for x in s.contact_fraction], "ms_per_tick": s.ms_per_tick,
                "ticks": s.ticks}
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
