#!/usr/bin/env python
"""Projector ablation: short projector trainings with different losses / layouts, each scored like
``lmm-studio eval`` (needs torch).

Every variant trains a fresh projector for --iterations on the shipped database, with latents from the
shipped compressor, then reports exact nearest-neighbour agreement, cost ratio and distances to the
true nearest frame on the eval's 4096 noisy queries and on the queries motion matching makes in 60 s of
builtin:random:1. This is how the shipped projector's losses were chosen (lmm/data/weights/README.md).

    python bench/projector_ablation.py [--iterations 3000] [--variants reference,shipped] [--json out.json]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

# name: (skip connection, loss weights, cell margin)
VARIANTS = {
    "reference": (False, {"features": 1.0, "latent": 5.0, "distance": 0.3, "cell": 0.0}, 0.1),
    "features5": (False, {"features": 5.0, "cell": 0.0}, 0.1),
    "features5_skip": (True, {"features": 5.0, "cell": 0.0}, 0.1),
    "cell5": (True, {"features": 5.0, "cell": 5.0}, 0.05),
    "cell50": (True, {"features": 5.0, "cell": 50.0}, 0.05),
    "cell50_margin0.1": (True, {"features": 5.0, "cell": 50.0}, 0.1),
    "cell100_features5": (True, {"features": 5.0, "cell": 100.0}, 0.1),
    "shipped": (True, {}, 0.1),
    "shipped_distance3": (True, {"distance": 3.0}, 0.1),
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iterations", type=int, default=3000)
    ap.add_argument("--batch", type=int, default=512)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--variants", default=",".join(VARIANTS), help=f"comma-separated, from: {', '.join(VARIANTS)}")
    ap.add_argument("--json", dest="json_path", help="write the results here")
    args = ap.parse_args()
    names = [v.strip() for v in args.variants.split(",") if v.strip()]
    unknown = [n for n in names if n not in VARIANTS]
    if unknown:
        ap.error(f"unknown variant(s): {', '.join(unknown)}")

    import torch

    from lmm.offline import training as T
    from lmm.offline.decompressor_training import compute_latents
    from lmm.offline.projector_training import PROJECTOR_WEIGHTS, train_projector
    from lmm.offline.training_data import prepare
    from lmm.data.build import load_or_build
    from lmm.offline.evaluation import projector_metrics, projector_runtime_agreement, run_controller
    from lmm.features import build_features
    from lmm.data.inputs import open_input
    from lmm.learned import DEFAULT_WEIGHTS, LMMNetworks
    from lmm.mm import MotionMatchingController
    from lmm.nn import MLP

    torch.set_num_threads(args.threads)
    db, _ = load_or_build()
    features = build_features(db)
    shipped = LMMNetworks.load(DEFAULT_WEIGHTS, db, features)
    compressor = T._load_networks(DEFAULT_WEIGHTS.with_name(T.COMPRESSOR_FILE), ["compressor"], db, features)[0]["compressor"]
    data = prepare(db, features)
    Z = compute_latents(compressor, data)
    mm = run_controller(MotionMatchingController(db, features), open_input("builtin:random:1", 60.0), 60.0)

    results = []
    print(f"{'variant':<20} {'agree':>6} {'within3':>7} {'cost':>6} {'proj-nn':>7} {'latent':>6} | {'rt agree':>8} {'rt cost':>7} "
          f"{'rt proj-nn':>10} | {'train s':>7}")
    for name in names:
        skip, weights, margin = VARIANTS[name]
        t0 = time.perf_counter()
        net, _ = train_projector(data, Z, T.StageSettings(args.iterations, args.batch, 2e-3), quiet=True,
                                 weights=weights, skip=skip, margin=margin)
        wall = time.perf_counter() - t0
        nets = dataclasses.replace(shipped, projector=MLP.from_spec(net.to_arrays("projector"), "projector",
                                                                    net.spec.to_dict()))
        m = projector_metrics(nets, features, Z=Z.numpy())
        m.update(projector_runtime_agreement(nets, features, mm["queries"]))
        row = {"variant": name, "skip": skip, "weights": {**PROJECTOR_WEIGHTS, **weights}, "margin": margin,
               "iterations": args.iterations, "train_s": round(wall, 1), **m}
        results.append(row)
        print(f"{name:<20} {m['nn_agreement']:6.3f} {m['nn_within_3_frames']:7.3f} {m['cost_ratio_median']:6.3f} "
              f"{m['projection_to_nn_median']:7.3f} {m['latent_error_mean_abs_std']:6.3f} | {m['nn_agreement_runtime']:8.3f} {m['cost_ratio_median_runtime']:7.3f} "
              f"{m['projection_to_nn_median_runtime']:10.3f} | {wall:7.0f}", flush=True)
    print(f"(query to nearest frame, median: {results[0]['query_to_nn_median']:.3f} eval, "
          f"{results[0]['query_to_nn_median_runtime']:.3f} run time; normalised feature units)")
    if args.json_path:
        Path(args.json_path).write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
