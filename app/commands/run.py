"""``lmm-studio run``: drive a controller headless from an input log or a built-in scenario.

    lmm-studio run --controller mm --input builtin:random:1 --seconds 600 \
        --record out/run.bvh --metrics-json out/metrics.json

Deterministic: the same input gives a byte-identical recording on the same machine. ``--record``
streams the character to BVH (crash-safe, see :mod:`lmm.data.recording`) and the input to CSV beside it
(``OUT.input.csv``, or ``--record-input``). ``--session OUT.lmmsession`` keeps the run as a session
(:mod:`lmm.session`: replay it with ``lmm-studio replay``), ``--events EVENTS.json`` changes the tuning and
resets the character at given ticks (the session's event format). Bad input (unreadable or broken logs, unknown scenarios,
bad presets or weights, an unwritable target) raises an :class:`lmm.errors.InputError` or ``OSError``
naming the file, line and column, which ``app/cli.py`` prints as one line (exit 1); bad numbers on the
command line are refused by argparse (exit 2). Every target is checked before the run starts.
"""
from __future__ import annotations

import sys
from pathlib import Path

from app.cli import number_in
from app.commands.session_common import add_session_run_arguments, check_outputs, session_run
from lmm.data.inputs import MAX_INPUT_SECONDS

#: Tick rates accepted (Hz). Below 1 Hz one tick is longer than every halflife and the search interval
#: (at most 1 s) the tuning allows; at 1000 Hz a recording's Frame Time is 1 ms, well inside what the
#: BVH reader accepts, and a tick is still ~1000 times float64's resolution of a day.
MIN_FPS, MAX_FPS = 1.0, 1000.0


def add_arguments(p) -> None:
    p.add_argument("--controller", default="mm", choices=("mm", "lmm"), help="which controller runs (default mm)")
    p.add_argument("--input", required=True, metavar="CSV|builtin:NAME",
                   help="an input log (CSV: time,left_x,left_y,right_x,right_y,walk,strafe) or a built-in "
                        "scenario: circle, zigzag, stop-and-go, strafe, turns, random:SEED")
    p.add_argument("--seconds", type=number_in(0.0, MAX_INPUT_SECONDS, unit="s"),
                   help=f"how long to run, 0..{MAX_INPUT_SECONDS:g} s (default: the log's length, 60 s for built-ins)")
    p.add_argument("--fps", type=number_in(MIN_FPS, MAX_FPS, unit="Hz"), default=60.0,
                   help=f"ticks per second, {MIN_FPS:g}..{MAX_FPS:g} (default 60)")
    p.add_argument("--record", metavar="OUT.bvh", help="stream the character's animation to this BVH file")
    p.add_argument("--record-input", metavar="PATH", help="stream the input to this CSV (default: OUT.input.csv)")
    p.add_argument("--metrics-json", metavar="PATH", help="write the run's metrics here as JSON")
    p.add_argument("--tuning", metavar="PRESET.json", help="a tuning preset (partial presets keep the defaults)")
    p.add_argument("--weights", help="LMM network weights (--controller lmm; default: the shipped ones)")
    p.add_argument("--manifest", help="dataset manifest (default: the shipped LAFAN1 locomotion set)")
    p.add_argument("--realtime", action="store_true", help="pace the ticks to the wall clock")
    talk = p.add_mutually_exclusive_group()
    talk.add_argument("--quiet", action="store_true", help="print nothing but errors")
    talk.add_argument("--verbose", action="store_true",
                      help="print every metric (default: the main ones; --metrics-json holds them all)")
    add_session_run_arguments(p)


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
    from lmm.data.inputs import open_input
    from lmm.tuning import Tuning

    # everything the user typed is checked before the (slower) database load, targets first: no output
    # may be an input or another output (the recording, its input log, the metrics, the session)
    record_input = None
    if args.record:
        out = Path(args.record)
        record_input = Path(args.record_input) if args.record_input else out.with_name(out.stem + ".input.csv")
    elif args.record_input:
        record_input = Path(args.record_input)
    outputs = [("--record", args.record), ("--record-input", record_input), ("--metrics-json", args.metrics_json),
               ("--session", args.session)]
    inputs = [("--input", None if str(args.input).startswith("builtin:") else args.input),
              ("--tuning", args.tuning), ("--events", args.events), ("--weights", args.weights)]
    if any(path for _, path in outputs):   # the manifest and its takes too (read only when there are outputs)
        from lmm.data.build import manifest_inputs
        inputs += manifest_inputs(args.manifest)
    check_outputs(outputs, inputs)
    source = open_input(args.input, args.seconds)
    preset = Tuning.read_preset(args.tuning) if args.tuning else None
    tuning = Tuning.from_preset(preset, args.tuning) if preset is not None else Tuning()
    seconds = args.seconds if args.seconds is not None else max(source.duration, 1.0 / args.fps)
    raw_events = None
    if args.events:
        from lmm.session.actions import read_events_file
        raw_events = read_events_file(args.events)
    if args.controller == "lmm" and args.weights:
        from lmm.data.weights import load as load_weights
        from lmm.learned import RUNTIME_NETWORKS
        load_weights(args.weights, require=RUNTIME_NETWORKS)  # metadata and arrays, before the database

    from lmm.data.build import load_or_build
    from lmm.features import build_features
    from lmm.data.recording import BVHRecorder
    from lmm.factory import make_controller
    from lmm.runner import run_headless

    db, _ = load_or_build(args.manifest)
    features = build_features(db)
    if preset is not None:  # now the channels are known: a misspelt feature_weights name is an error
        tuning = Tuning.from_preset(preset, args.tuning, channels=[ch.name for ch in features.layout])
    # headless: nothing shows the learned controller's debug nearest-neighbour comparison (the motion
    # does not depend on it), so it is not computed
    controller = make_controller(args.controller, db, features, tuning, args.weights, debug_comparison=False)
    if not args.quiet:
        from lmm.data_fit import fit_warnings
        for line in fit_warnings(db, tuning):   # speeds beyond the data, bone roles that look wrong
            print(f"warning: {line}", file=sys.stderr)

    recorder = writer = None
    if record_input is not None:
        from lmm.data.inputs import InputCsvWriter
        writer = InputCsvWriter(record_input)
    if args.record:
        try:
            recorder = BVHRecorder(Path(args.record), db, fps=args.fps)
        except BaseException:
            _close(writer)
            raise
    notes = []    # each distinct search note (a tag filter or bias that cannot apply), as it first appears

    def note_once(pose, snap):
        if snap.search_note and snap.search_note not in notes:
            notes.append(snap.search_note)
            print(f"note: tick {snap.tick}: {snap.search_note}", file=sys.stderr)

    session = None
    try:
        session = session_run(args, raw_events, db, features, tuning, controller, seconds)
        hooks = {} if session is None else {"before_step": session.before_step, "after_step": session.after_step}
        import numpy as np

        # a network given absurd weights overflows: numpy's warnings would be lines on every tick; the
        # pose guard (lmm.metrics.pose_problem) reports it once below instead
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            metrics = run_headless(controller, source, seconds, dt=1.0 / args.fps, recorder=recorder,
                                   input_writer=writer, realtime=args.realtime, on_step=note_once, **hooks)
    finally:
        # the streams are closed even when one fails (a full disk); the first error is the one reported
        close_errors = [e for e in (_close(recorder), _close(writer), _close(session)) if e is not None]
    if close_errors:
        raise close_errors[0]
    if metrics["non_finite_ticks"]:   # once, with the first tick: those poses were not recorded
        print(f"note: tick {metrics['first_non_finite_tick']}: the {args.controller} pose is "
              f"{metrics['first_non_finite_problem']}; {metrics['non_finite_ticks']} such ticks were left out of "
              f"the metrics{' and the recording' if args.record else ''}", file=sys.stderr)

    # the same ground skating rule over the database's source takes, printed beside the run's
    from lmm.metrics import source_ground_skating
    metrics["ground_skating_fraction_source"] = source_ground_skating(db)["fraction"]
    report = {"controller": args.controller, "input": args.input, "seconds": seconds, "fps": args.fps,
              "frames": metrics["ticks"], "metrics": metrics, "search_notes": notes}
    if args.session:
        report["session"] = str(args.session)
    if args.record:
        report["recording"] = {"bvh": str(args.record), "frames": recorder.frames_written,
                               "input_csv": str(writer.path)}
    if args.metrics_json:
        from lmm.data.jsonio import write_json
        write_json(args.metrics_json, report)
    if not args.quiet:
        print(f"{args.controller} on {args.input}: {seconds:g} s, {metrics['ticks']} ticks")
        print(metrics_summary(metrics, every=args.verbose))
    return 0


#: the metrics ``run`` prints by default, in this order (those a run has): skating, pops and snaps, how
#: well the path is followed, how often it searches and switches, the step cost, broken poses
SUMMARY_METRICS = ("foot_skating_cm_s", "foot_skating_max_cm_s", "ground_skating_fraction",
                   "ground_skating_fraction_source", "quality_pops_per_min", "quality_knee_snaps_per_min",
                   "quality_acceleration_p99_slow_ratio", "quality_acceleration_p99_slow_played_ratio",
                   "quality_jerk_p99_ratio", "trajectory_error_mean_m", "transitions_per_s", "searches_per_s",
                   "step_us_median", "non_finite_ticks")


def metrics_summary(metrics: dict, every: bool = False) -> str:
    """The main metrics as a two-column table and a line naming how many more there are (all of them
    with ``every``): the whole table is over 40 lines, more than a terminal shows."""
    from lmm.metrics import format_metrics

    if every:
        return format_metrics(metrics)
    shown = {k: metrics[k] for k in SUMMARY_METRICS if k in metrics}
    more = len(metrics) - len(shown)
    return format_metrics(shown) + (f"\n({more} more metrics: --verbose, or --metrics-json PATH)" if more else "")
