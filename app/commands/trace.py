"""``lmm-studio trace``: a session's per-tick trace as CSV or parquet (columns: :mod:`lmm.session.trace`).

    lmm-studio trace run.lmmsession --out run.csv
    lmm-studio trace run.lmmsession --out run.parquet     # needs pyarrow (pip install pyarrow)

The session is replayed with every fingerprint checked; a replay that differs is an error (exit 1).
"""
from __future__ import annotations

import sys
from pathlib import Path

from app.commands.session_common import check_outputs, open_with_database


def add_arguments(p) -> None:
    p.add_argument("session", metavar="SESSION", help="a session file (run --session, or the studio's)")
    p.add_argument("--out", required=True, metavar="T.csv|T.parquet", help="the trace file (by its suffix)")
    p.add_argument("--manifest", help="the database's manifest (default: the one the session names)")
    p.add_argument("--weights", help="LMM networks (default: the file the session names; must be the same)")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")


def main(args) -> int:
    from lmm.errors import InputError
    from lmm.session import trace
    from lmm.session.player import SessionPlayer

    suffix = Path(args.out).suffix.lower()
    if suffix not in (".csv", ".parquet"):
        raise InputError(f"{args.out}: --out must end in .csv or .parquet")
    if suffix == ".parquet":
        try:
            import pyarrow  # noqa: F401
        except ImportError:
            raise InputError(f"{args.out}: parquet needs the optional pyarrow (pip install pyarrow); "
                             f"or write --out {Path(args.out).with_suffix('.csv').name}") from None
    check_outputs([("--out", args.out)], [args.session])
    session, db, features, weights = open_with_database(args.session, args.manifest, args.weights)
    player = SessionPlayer(session, db, features, weights=weights, debug_comparison=True)
    header = trace.columns(features.names)
    write = trace.write_csv if suffix == ".csv" else trace.write_parquet
    rows = write(args.out, header, trace.trace_rows(player, db, features))
    session.close()
    wrong = player.unexpected_mismatches()
    if wrong:
        print(f"lmm-studio trace: error: {args.session}: the replay differs from the recording at tick "
              f"{wrong[0][0]} (controller {wrong[0][1]}); the trace {args.out} shows the replay", file=sys.stderr)
        return 1
    if not args.quiet:
        print(f"{args.out}: {rows} rows x {len(header)} columns ({session.ticks} ticks, "
              f"{len(player.controllers)} controller(s)); all {player.checked} fingerprints match")
    return 0
