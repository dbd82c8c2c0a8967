"""``lmm-studio replay``: re-simulate a session headless and prove it matches, or branch it.

    lmm-studio replay run.lmmsession --record again.bvh --metrics-json m.json
    lmm-studio replay run.lmmsession --tuning B.json --from-tick 600      # a branch

Every recorded pose fingerprint is compared (one a second per controller): a replay that differs prints the
first tick that differs and exits 1. With ``--tuning`` the preset's fields are set on top of the tuning at
``--from-tick`` (default 0) and the recorded tuning changes after it are not applied (actions are): the
fingerprints before that tick must match, those after need not (their count is reported). A session from
another database or other networks is refused in one line; another program version is a one-line warning.
"""
from __future__ import annotations

import sys
import time

from app.cli import number_in
from app.commands.session_common import check_outputs, open_with_database


def add_arguments(p) -> None:
    p.add_argument("session", metavar="SESSION", help="a session file (run --session, or the studio's)")
    p.add_argument("--record", metavar="OUT.bvh", help="stream one controller's animation to this BVH file (from "
                   "the tick the session's recording starts at: a studio recording's)")
    p.add_argument("--controller", metavar="NAME", help="the controller --record records (default: the first)")
    p.add_argument("--metrics-json", metavar="PATH", help="write each controller's metrics and the check here")
    p.add_argument("--tuning", metavar="PRESET.json", help="branch: these tuning values from --from-tick on")
    p.add_argument("--from-tick", type=number_in(0, 86_400_000, integer=True), default=0, metavar="N",
                   help="the tick the --tuning branch starts at (default 0)")
    p.add_argument("--manifest", help="the database's manifest (default: the one the session names)")
    p.add_argument("--weights", help="LMM networks (default: the file the session names; must be the same)")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")


def read_branch(args):
    """The ``--tuning`` preset (a dict, checked field by field now; channels once the database is known)."""
    if not args.tuning:
        return None
    from lmm.tuning import Tuning

    preset = Tuning.read_preset(args.tuning)
    Tuning.from_preset(preset, args.tuning)
    return preset


def start_player(args, session, db, features, weights, branch, debug_comparison=False):
    """A :class:`lmm.session.player.SessionPlayer` for ``args`` (``--from-tick`` checked against the session)."""
    from lmm.errors import InputError
    from lmm.session.player import SessionPlayer
    from lmm.tuning import Tuning

    if args.from_tick > session.ticks:
        raise InputError(f"--from-tick {args.from_tick} is after the session's last tick ({session.ticks} ticks)")
    if branch is not None:
        Tuning.from_preset(branch, args.tuning, channels=[ch.name for ch in features.layout])
    return SessionPlayer(session, db, features, branch=branch, from_tick=args.from_tick, weights=weights,
                         debug_comparison=debug_comparison)


def main(args) -> int:
    from lmm.errors import InputError
    from lmm.metrics import MotionMetrics

    check_outputs([("--record", args.record), ("--metrics-json", args.metrics_json)], [args.session, args.tuning])
    branch = read_branch(args)
    session, db, features, weights = open_with_database(args.session, args.manifest, args.weights)
    player = start_player(args, session, db, features, weights, branch)
    names = list(player.controllers)
    recorded = args.controller or names[0]
    if recorded not in names:
        raise InputError(f"--controller {recorded[:40]!r}: the session has {', '.join(names)}")
    recorder = None
    if args.record:
        from lmm.data.recording import BVHRecorder
        recorder = BVHRecorder(args.record, db, fps=session.fps)
    metrics = {name: MotionMetrics(db) for name in names}
    start = time.perf_counter()
    record_from = session.recording_from     # a studio session: its recording starts mid-session
    try:
        while not player.done:
            tick = player.tick
            poses, snaps = player.step()
            usable = {name: metrics[name].update(snap) for name, snap in snaps.items()}
            if recorder is not None and tick >= record_from and usable[recorded]:   # never a NaN pose
                recorder.write(poses[recorded])
    finally:
        if recorder is not None:
            recorder.close()
    wall = time.perf_counter() - start
    wrong = player.unexpected_mismatches()
    report = {"session": str(args.session), "ticks": session.ticks, "seconds": session.ticks * session.dt,
              "fps": session.fps, "replay_wall_s": wall, "closed": session.meta["closed"],
              "branch": None if branch is None else {"tuning": str(args.tuning), "from_tick": args.from_tick},
              "fingerprints": {"checked": player.checked, "differing": len(player.mismatches),
                               "unexpected": [list(m) for m in wrong[:20]]},
              "controllers": {name: m.result() for name, m in metrics.items()}}
    if args.metrics_json:
        from lmm.data.jsonio import write_json
        write_json(args.metrics_json, report)
    session.close()
    if wrong:
        tick, name = wrong[0]
        print(f"lmm-studio replay: error: {args.session}: the replay differs from the recording at tick {tick} "
              f"({tick * session.dt:.3f} s, controller {name}); {len(wrong)} of {player.checked} fingerprints "
              f"differ", file=sys.stderr)
        return 1
    if not args.quiet:
        what = f"{session.ticks} ticks ({session.ticks * session.dt:g} s) in {wall:.2f} s"
        if branch is None:
            print(f"replayed {what}: all {player.checked} fingerprints match")
        else:
            print(f"branch from tick {args.from_tick}: replayed {what}; fingerprints before the branch match, "
                  f"{len(player.mismatches)} after it differ")
    return 0
