"""Cost per 60 Hz tick of the physics plausibility (lmm.physics.plausibility): inverse dynamics, contact
forces by NNLS and the foot figures, over 10 s of database frames, and of one tick of the imitation
environment (lmm.physics.env: 8 physics substeps with PD). Prints medians of 5 repeats; needs mujoco.

    PYTHONPATH=. python bench/physics_cost.py
"""
from __future__ import annotations

import time

import numpy as np


def main() -> None:
    from lmm.data.build import load_or_build
    from lmm.physics.body import body_for_database
    from lmm.physics.env import ImitationEnv
    from lmm.physics.plausibility import plausibility

    db, _ = load_or_build(None)
    body = body_for_database(db)
    start = int(db.range_starts[1])
    n = 600
    rot, pos = db.global_transforms(slice(start, start + n))
    times = []
    for _ in range(5):
        t = time.perf_counter()
        result = plausibility(body, pos, rot, db.fps)
        times.append((time.perf_counter() - t) / n)
    print(f"plausibility      {np.median(times) * 1e6:8.1f} us per 60 Hz tick ({n} frames, {body.nv} dofs, "
          f"residual median {np.median(result.residual_force_bw):.3f} BW)")
    env = ImitationEnv(db)
    env.reset(start + 10)
    steps = 120
    times = []
    for _ in range(5):
        env.reset(start + 10)
        t = time.perf_counter()
        for _ in range(steps):
            env.step(np.zeros(env.action_size))
        times.append((time.perf_counter() - t) / steps)
    print(f"imitation env     {np.median(times) * 1e6:8.1f} us per 60 Hz tick ({env.substeps} substeps, PD + rewards)")


if __name__ == "__main__":
    main()
