"""``lmm-studio eval``: quality metrics of the learned motion matching networks (numpy, no torch).

The terminal gets a line per group of metrics; the whole set goes to ``--json OUT`` (``-``: standard
output, no plots by default)."""
from __future__ import annotations

import json
import sys
from pathlib import Path

from app.cli import number_in
from lmm.data.inputs import MAX_INPUT_SECONDS

#: Noisy queries for the projector metrics: each is a feature vector (~100 bytes) and a brute-force
#: nearest-neighbour search over the database (~1 ms); 100,000 take ~10 MB and a couple of minutes.
MAX_QUERIES = 100_000


def add_arguments(p) -> None:
    p.add_argument("--weights", help="runtime weights (default: the shipped lmm/data/weights/default.npz)")
    p.add_argument("--compressor", help="compressor weights (default: compressor.npz beside --weights)")
    p.add_argument("--json", dest="json_path", metavar="OUT", help="write the metrics here as JSON; - prints them")
    p.add_argument("--plots", help="folder for the PNG plots (default: beside --json, else no plots)")
    p.add_argument("--input", default="builtin:random:1", help="input for the MM vs LMM comparison")
    p.add_argument("--seconds", type=number_in(1.0, MAX_INPUT_SECONDS, unit="s"), default=60.0,
                   help=f"length of the MM vs LMM run, 1..{MAX_INPUT_SECONDS:g} s (default 60)")
    p.add_argument("--queries", type=number_in(1, MAX_QUERIES, integer=True), default=4096,
                   help=f"noisy queries for the projector metrics, 1..{MAX_QUERIES} (default 4096)")
    p.add_argument("--manifest", help="dataset manifest (default: the shipped LAFAN1 locomotion set)")
    p.add_argument("--reconstruction", action="store_true",
                   help="instead: drive MM and LMM with the input derived from held-out takes and compare "
                        "their motion with the takes (DTW rotation/position error, root path, skating), beside "
                        "the error of holding each take's mean pose and of the database's nearest pose")
    p.add_argument("--heldout", help="with --reconstruction: the held-out list (default: lmm/data/heldout.json)")
    p.add_argument("--data", help="with --reconstruction: folder of the 'shared:' takes "
                                  "(default: $LMM_LAFAN1_DIR or ../shared/data/lafan1 beside the repository)")


def _json_file(args):
    """The file ``--json`` names (None for none or ``-``, standard output)."""
    return None if args.json_path in (None, "-") else args.json_path


def main(args) -> int:
    if args.reconstruction:
        return reconstruction(args)
    from app.commands.extras import require
    if (_json_file(args) or args.plots) and not require("eval", "matplotlib", purpose=" for its plots"):
        return 2
    from lmm.data.build import load_or_build, manifest_inputs
    from lmm.data.inputs import open_input
    from lmm.data.outputs import check_outputs
    from lmm.data.weights import load as load_weights
    from lmm.offline.evaluation import evaluate, load_compressor, read_loss_csv
    from lmm.reporting import plot_training
    from lmm.features import build_features
    from lmm.learned import DEFAULT_WEIGHTS, RUNTIME_NETWORKS, LMMNetworks

    # everything the user named is checked before the database load and the minutes of evaluation
    weights = Path(args.weights) if args.weights else DEFAULT_WEIGHTS
    comp = Path(args.compressor) if args.compressor else weights.with_name("compressor.npz")
    plots_dir = args.plots or (str(Path(_json_file(args)).parent) if _json_file(args) else None)
    check_outputs([("--json", _json_file(args))] + [("--plots", Path(plots_dir) / name) for name in TRAINING_PLOTS
                                                  if plots_dir],
                  [("--weights", weights), ("--compressor", comp), ("--input", _input_file(args.input)),
                   *manifest_inputs(args.manifest)])
    load_weights(weights, require=RUNTIME_NETWORKS)  # WeightsError names the file and field
    load_weights(comp, require=["compressor"])
    open_input(args.input, args.seconds)

    db, _ = load_or_build(args.manifest)
    features = build_features(db)
    nets = LMMNetworks.load(weights, db, features)
    compressor = load_compressor(comp, db, features)
    log = lambda msg: print(msg, file=sys.stderr)  # noqa: E731
    metrics, artifacts = evaluate(db, features, nets, compressor, args.input, args.seconds, args.queries, log)
    if plots_dir:
        loss_csv = weights.with_name("training_log.csv")
        metrics["plots"] = plot_training(plots_dir, read_loss_csv(loss_csv) if loss_csv.exists() else None, artifacts)
    from lmm.data.jsonio import json_safe, write_json

    if args.json_path == "-":
        print(json.dumps(json_safe(metrics), indent=2))
    elif args.json_path:
        write_json(args.json_path, metrics)
        print(f"metrics written to {args.json_path}", file=sys.stderr)
    if plots_dir:
        print(f"plots in {plots_dir}", file=sys.stderr)
    return 0


#: the PNGs lmm.reporting.plot_training writes into the plots folder (checked as outputs before the work)
TRAINING_PLOTS = ("training_losses.png", "latent_traces.png", "per_joint_error.png")


def _input_file(spec):
    """The file an ``--input`` names, or None for a built-in scenario."""
    return None if str(spec).startswith("builtin:") else spec


def reconstruction(args) -> int:
    """``eval --reconstruction``: the held-out takes through MM and LMM (see :mod:`lmm.reconstruction`)."""
    import time

    from app.commands.extras import require
    from lmm import DEFAULT_MANIFEST
    from lmm.data.build import load_or_build, manifest_inputs
    from lmm.data.manifest import load_manifest
    from lmm.data.outputs import check_outputs
    from lmm.factory import make_controllers
    from lmm.features import build_features
    from lmm.reconstruction import HELDOUT_FILE, PoseOracle, format_table, load_heldout, run_take, summarize
    from lmm.reporting import plot_rotation_errors
    from lmm.tuning import Tuning

    plots_dir = args.plots or (str(Path(_json_file(args)).parent) if _json_file(args) else None)
    if plots_dir and not require("eval", "matplotlib", purpose=" for its plots"):
        return 2
    takes, missing = load_heldout(args.heldout or HELDOUT_FILE, args.data)
    for line in missing:
        print(line, file=sys.stderr)
    if not takes:
        print("lmm-studio eval: error: no held-out take found (see --data)", file=sys.stderr)
        return 1
    check_outputs([("--json", _json_file(args)), ("--plots", Path(plots_dir) / "reconstruction.png" if plots_dir else None)],
                  [("--heldout", args.heldout), *manifest_inputs(args.manifest)])
    manifest = load_manifest(args.manifest or DEFAULT_MANIFEST)
    db, _ = load_or_build(args.manifest)
    features = build_features(db)
    controllers, problems = make_controllers(db, features, Tuning(), args.weights)
    for problem, _ in problems:
        print(problem, file=sys.stderr)
    results = []
    oracle = PoseOracle(db, manifest.hips_forward_axis)   # the nearest-frame baseline's poses, built once
    for take in takes:
        t0 = time.perf_counter()
        results.append(run_take(take, db, features, manifest, controllers, oracle=oracle))
        print(f"{take.name} [{take.frames[0]}:{take.frames[1]}]: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    names = list(controllers)
    summary = summarize(results, names)
    print(format_table(results, summary, names))
    if args.json_path == "-":
        from lmm.data.jsonio import json_safe
        print(json.dumps(json_safe({"takes": results, "summary": summary}), indent=2))
    elif args.json_path:
        from lmm.data.jsonio import write_json
        write_json(args.json_path, {"takes": results, "summary": summary})
    if plots_dir:
        plot_rotation_errors(results, names, Path(plots_dir) / "reconstruction.png")
    return 0
