"""``lmm-studio ab``: arm A (a session as recorded) against arm B (another tuning from a tick on).

    lmm-studio ab run.lmmsession --tuning B.json --from-tick 600 --json ab.json --report ab/

Both arms replay the same recorded input and actions in lockstep (:mod:`lmm.session.ab`). The JSON holds
both arms' metrics per controller and a summary of the per-tick pose difference (0 before the branch);
``--report DIR`` writes one PNG per controller (difference, cost and transitions over time).
"""
from __future__ import annotations

import sys

from app.cli import number_in
from app.commands.session_common import check_outputs, open_with_database


def add_arguments(p) -> None:
    p.add_argument("session", metavar="SESSION", help="a session file (run --session, or the studio's)")
    p.add_argument("--tuning", required=True, metavar="B.json", help="arm B's tuning preset (fields set on top)")
    p.add_argument("--from-tick", type=number_in(0, 86_400_000, integer=True), default=0, metavar="N",
                   help="the tick arm B starts differing at (default 0)")
    p.add_argument("--json", metavar="OUT", help="write the comparison here as JSON")
    p.add_argument("--report", metavar="DIR", help="write PNG plots into this folder")
    p.add_argument("--manifest", help="the database's manifest (default: the one the session names)")
    p.add_argument("--weights", help="LMM networks (default: the file the session names; must be the same)")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")


def main(args) -> int:
    from pathlib import Path

    from app.commands.replay import read_branch
    from lmm.errors import InputError
    from lmm.session import ab
    from lmm.tuning import Tuning

    check_outputs([("--json", args.json)], [args.session, args.tuning])
    if args.report:
        report_dir = Path(args.report)
        for name in ("ab_mm.png", "ab_lmm.png"):
            check_outputs([("--report", report_dir / name)], [args.session, args.tuning])
    branch = read_branch(args)
    session, db, features, weights = open_with_database(args.session, args.manifest, args.weights)
    if args.from_tick > session.ticks:
        raise InputError(f"--from-tick {args.from_tick} is after the session's last tick ({session.ticks} ticks)")
    Tuning.from_preset(branch, args.tuning, channels=[ch.name for ch in features.layout])
    report, series = ab.compare(session, db, features, branch, args.from_tick, weights)
    report["tuning_b"] = str(args.tuning)
    if args.report:
        report["plots"] = ab.plot(series, report, args.report)
    if args.json:
        from lmm.data.jsonio import write_json
        write_json(args.json, report)
    session.close()
    if report["arm_a"]["fingerprints_differing"]:
        tick, name = report["arm_a"]["first_differing"]
        print(f"lmm-studio ab: error: {args.session}: arm A differs from the recording at tick {tick} "
              f"(controller {name})", file=sys.stderr)
        return 1
    if not args.quiet:
        for name, c in report["controllers"].items():
            d = c["pose_difference_m"]
            print(f"{name}: before tick {args.from_tick} largest difference {d['before_branch_max']:g} m; after: "
                  f"mean {d['after_branch_mean']:.4f} m, largest {d['after_branch_max']:.4f} m, first differing "
                  f"tick {d['first_differing_tick']}; transitions A {c['transitions_after_branch']['a']} "
                  f"B {c['transitions_after_branch']['b']}; foot skating A "
                  f"{c['a']['foot_skating_cm_s']:.3g} B {c['b']['foot_skating_cm_s']:.3g} cm/s")
    return 0
