"""``lmm-studio eval``: quality metrics of the learned motion matching networks (numpy, no torch)."""
from __future__ import annotations

import json
import sys
from pathlib import Path


def add_arguments(p) -> None:
    p.add_argument("--weights", help="runtime weights (default: the shipped lmm/data/weights/default.npz)")
    p.add_argument("--compressor", help="compressor weights (default: compressor.npz beside --weights)")
    p.add_argument("--json", dest="json_path", help="write the metrics here as JSON")
    p.add_argument("--plots", help="folder for the PNG plots (default: beside --json, else no plots)")
    p.add_argument("--input", default="builtin:random:1", help="input for the MM vs LMM comparison")
    p.add_argument("--seconds", type=float, default=60.0, help="length of the MM vs LMM run (s)")
    p.add_argument("--queries", type=int, default=4096, help="noisy queries for the projector metrics")
    p.add_argument("--manifest", help="dataset manifest (default: the shipped LAFAN1 locomotion set)")


def main(args) -> int:
    from app.commands.extras import require
    if (args.json_path or args.plots) and not require("eval", "matplotlib", purpose=" for its plots"):
        return 2
    from lmm.data.database import load_or_build
    from lmm.offline.evaluation import evaluate, load_compressor, write_plots
    from lmm.features import build_features
    from lmm.learned import DEFAULT_WEIGHTS, LMMNetworks
    from lmm.data.weights import WeightsError

    db, _ = load_or_build(args.manifest)
    features = build_features(db)
    weights = Path(args.weights) if args.weights else DEFAULT_WEIGHTS
    comp = Path(args.compressor) if args.compressor else weights.with_name("compressor.npz")
    try:
        nets = LMMNetworks.load(weights, db, features)
        compressor = load_compressor(comp, db, features)
    except WeightsError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    log = lambda msg: print(msg, file=sys.stderr)  # noqa: E731
    metrics, artifacts = evaluate(db, features, nets, compressor, args.input, args.seconds, args.queries, log)
    plots_dir = args.plots or (str(Path(args.json_path).parent) if args.json_path else None)
    if plots_dir:
        loss_csv = weights.with_name("training_log.csv")
        metrics["plots"] = write_plots(plots_dir, artifacts, loss_csv)
    from lmm.data.jsonio import json_safe, write_json

    if args.json_path:
        write_json(args.json_path, metrics)
    print(json.dumps(json_safe(metrics), indent=2))
    return 0
