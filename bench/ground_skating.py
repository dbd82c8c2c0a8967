"""Ground skating of BVH recordings (or any takes) beside the database's source takes, one rule for all
(:mod:`lmm.metrics`): the fraction of ground-level toe steps faster than 30 cm/s.

    python bench/ground_skating.py out/mm.bvh out/lmm.bvh [--manifest M]

Prints, per file, the fraction with the toe's own floor (its low percentile, the rule ``run`` reports)
and with the floor at y = 0, then the source figure of the database.
"""
from __future__ import annotations

import argparse

import numpy as np

from lmm.data import bvh
from lmm.data.build import load_or_build
from lmm.metrics import ground_skating, source_ground_skating


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("files", nargs="+")
    p.add_argument("--manifest")
    p.add_argument("--scale", type=float, default=100.0, help="file units per metre (recordings: 100)")
    args = p.parse_args()
    db, _ = load_or_build(args.manifest)
    toe_names = [db.names[db.bone("left_toe")], db.names[db.bone("right_toe")]]
    for path in args.files:
        anim = bvh.load(path)
        toes = anim.global_positions()[:, [anim.names.index(n) for n in toe_names]] / args.scale
        own = ground_skating(toes, anim.fps)
        zero = ground_skating(toes, anim.fps, floor_m=0.0)
        print(f"{path}: {own['fraction']:.3f} ({own['skating_steps']} of {own['ground_steps']} ground-level steps); "
              f"floor at y=0: {zero['fraction']:.3f} ({zero['skating_steps']} of {zero['ground_steps']})")
    src = source_ground_skating(db)
    print(f"source takes ({db.name}): {src['fraction']:.3f} ({src['skating_steps']} of {src['ground_steps']})")


if __name__ == "__main__":
    main()
