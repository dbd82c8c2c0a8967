"""``lmm-studio run``: drive a controller headless from an input log or a built-in scenario.

    lmm-studio run --controller mm --input builtin:random:1 --seconds 600 \
        --record out/run.bvh --metrics-json out/metrics.json

Deterministic: the same input gives a byte-identical recording on the same machine. ``--record``
streams the character to BVH (crash-safe, see :mod:`lmm.data.recording`) and the input to CSV beside it
(``OUT.input.csv``, or ``--record-input``). Bad input (unreadable or broken logs, unknown scenarios,
bad presets) prints one ``error: ...`` line naming the file, line and column and exits with 2.
"""
from __future__ import annotations

import sys
from pathlib import Path


def add_arguments(p) -> None:
    p.add_argument("--controller", default="mm", choices=("mm", "lmm"), help="which controller runs (default mm)")
    p.add_argument("--input", required=True, metavar="CSV|builtin:NAME",
                   help="an input log (CSV: time,left_x,left_y,right_x,right_y,walk,strafe) or a built-in "
                        "scenario: circle, zigzag, stop-and-go, strafe, turns, random:SEED")
    p.add_argument("--seconds", type=float, help="how long to run (default: the log's length, 60 s for built-ins)")
    p.add_argument("--fps", type=float, default=60.0, help="ticks per second (default 60)")
    p.add_argument("--record", metavar="OUT.bvh", help="stream the character's animation to this BVH file")
    p.add_argument("--record-input", metavar="PATH", help="stream the input to this CSV (default: OUT.input.csv)")
    p.add_argument("--metrics-json", metavar="PATH", help="write the run's metrics here as JSON")
    p.add_argument("--tuning", metavar="PRESET.json", help="a tuning preset (partial presets keep the defaults)")
    p.add_argument("--weights", help="LMM network weights (--controller lmm; default: the shipped ones)")
    p.add_argument("--manifest", help="dataset manifest (default: the shipped LAFAN1 locomotion set)")
    p.add_argument("--realtime", action="store_true", help="pace the ticks to the wall clock")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")


def _error(message: str, code: int = 2) -> int:
    print(f"error: {message}", file=sys.stderr)
    return code


def _close(stream) -> OSError | None:
    """Close a recording stream; the error instead of raising it."""
    if stream is None:
        return None
    try:
        stream.close()
    except OSError as e:
        return e
    return None


def main(args) -> int:
    from lmm.data.inputs import InputError, open_input
    from lmm.tuning import Tuning, TuningError

    # everything the user typed is checked before the (slower) database load
    if not args.fps > 0:
        return _error(f"--fps must be positive, got {args.fps}")
    if args.seconds is not None and not args.seconds >= 0:
        return _error(f"--seconds must be >= 0, got {args.seconds}")
    try:
        source = open_input(args.input, args.seconds)
    except InputError as e:
        return _error(str(e))
    try:
        tuning = Tuning.load(args.tuning) if args.tuning else Tuning()
    except TuningError as e:
        return _error(str(e))
    except OSError as e:
        return _error(f"{args.tuning}: cannot read the tuning preset ({e.strerror})")
    seconds = args.seconds if args.seconds is not None else max(source.duration, 1.0 / args.fps)

    from lmm.data.bvh import BVHError
    from lmm.data.database import DatabaseError, load_or_build
    from lmm.features import build_features
    from lmm.data.manifest import ManifestError
    from lmm.data.recording import BVHRecorder
    from lmm.factory import make_controller
    from lmm.runner import run_headless

    try:
        db, _ = load_or_build(args.manifest)
    except (BVHError, ManifestError, DatabaseError) as e:
        return _error(str(e), 1)
    features = build_features(db)
    try:
        controller = make_controller(args.controller, db, features, tuning, args.weights)
    except TuningError as e:
        return _error(str(e))
    except Exception as e:  # e.g. missing or broken network weights
        return _error(f"cannot start the {args.controller} controller: {e}", 1)

    recorder = writer = None
    try:
        if args.record:
            from lmm.data.inputs import InputCsvWriter
            out = Path(args.record)
            out.parent.mkdir(parents=True, exist_ok=True)
            input_path = Path(args.record_input) if args.record_input else out.with_name(out.stem + ".input.csv")
            writer = InputCsvWriter(input_path)
            recorder = BVHRecorder(out, db, fps=args.fps)
        elif args.record_input:
            from lmm.data.inputs import InputCsvWriter
            Path(args.record_input).parent.mkdir(parents=True, exist_ok=True)
            writer = InputCsvWriter(args.record_input)
    except OSError as e:
        return _error(f"cannot write the recording: {e}", 1)
    from lmm.data.stream import StreamWriteError
    try:
        try:
            metrics = run_headless(controller, source, seconds, dt=1.0 / args.fps, recorder=recorder,
                                   input_writer=writer, realtime=args.realtime)
        finally:
            # both streams are closed even when one failed; each keeps its last complete flush
            close_errors = [e for e in (_close(recorder), _close(writer)) if e is not None]
        if close_errors:
            raise close_errors[0]
    except StreamWriteError as e:   # a full disk: the recording is valid up to its last flush, or absent
        return _error(f"cannot write the recording: {e}", 1)

    # the same ground skating rule over the database's source takes, printed beside the run's
    from lmm.metrics import source_ground_skating
    metrics["ground_skating_fraction_source"] = source_ground_skating(db)["fraction"]
    report = {"controller": args.controller, "input": args.input, "seconds": seconds, "fps": args.fps,
              "frames": metrics["ticks"], "metrics": metrics}
    if args.record:
        report["recording"] = {"bvh": str(args.record), "frames": recorder.frames_written,
                               "input_csv": str(writer.path)}
    if args.metrics_json:
        from lmm.data.jsonio import write_json
        write_json(args.metrics_json, report)
    if not args.quiet:
        from lmm.metrics import format_metrics
        print(f"{args.controller} on {args.input}: {seconds:g} s, {metrics['ticks']} ticks")
        print(format_metrics(metrics))
    return 0
