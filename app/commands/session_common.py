"""What ``run --session/--events``, ``replay``, ``trace`` and ``ab`` share: output targets that never
overwrite an input, a session opened with its database, and the session side of ``run``."""
from __future__ import annotations

import sys
from lmm.errors import InputError


def check_outputs(outputs, inputs) -> None:
    """Every command's one output check (:func:`lmm.data.outputs.check_outputs`): an output that is an
    input, another output or a special file is refused in one line, the rest probed and locked."""
    from lmm.data.outputs import check_outputs as check

    check(outputs, inputs)


def open_with_database(path, manifest=None, weights=None):
    """``(session, db, features)``: the session checked, its database loaded (``manifest``, default the
    recorded one) and compared with the recording; warnings are printed as one line each."""
    from lmm.data.build import load_or_build
    from lmm.features import build_features
    from lmm.session.reader import check_identity, open_session

    session = open_session(path)
    recorded = session.database["manifest"] or None
    db, _ = load_or_build(manifest if manifest is not None else recorded)
    weights_map = {name: weights for name, (kind, _, _) in session.controllers.items()
                   if kind == "lmm" and weights}
    for line in check_identity(session, db, weights_map):
        print(f"warning: {line}", file=sys.stderr)
    return session, db, build_features(db), weights_map


def add_session_run_arguments(p) -> None:
    p.add_argument("--session", metavar="OUT.lmmsession",
                   help="keep the run as a session file (input, tuning changes, actions, pose fingerprints)")
    p.add_argument("--events", metavar="EVENTS.json",
                   help="tuning changes and actions at given ticks ({\"events\": [{tick, kind, payload}]}, "
                        "the session's own event format)")


def session_run(args, raw_events, db, features, tuning, controller, seconds: float):
    """The session side of ``run`` (a :class:`lmm.session.player.SessionRecorder`), or None without
    ``--session`` and ``--events`` (then the run is exactly as before). ``raw_events``: the events file's
    list (read before the database loads), checked here against the tuning and the database."""
    if not (args.session or args.events):
        return None
    from lmm.session.actions import check_events
    from lmm.session.player import SessionRecorder
    from lmm.session.writer import SessionWriter

    # the database's own channels and tags get entries, so events (and a later replay) can name them
    tuning.name_database_entries({ch.name: float(w) for ch, w in zip(features.layout, features.weights)},
                                 db.tag_names)
    n_ticks = int(round(seconds / (1.0 / args.fps)))     # as run_headless counts them
    events = []
    if args.events:
        events = check_events(raw_events, tuning, [controller.name], db.n_frames, args.events,
                              last_tick=max(n_ticks - 1, 0))
    writer = None
    if args.session:
        writer = SessionWriter(args.session, fps=args.fps, db=db, manifest=args.manifest,
                               controllers={controller.name: controller}, tuning=tuning,
                               start={"input": args.input, "seconds": seconds, "reset": {}})
    return SessionRecorder(tuning, {controller.name: controller}, events, writer)
