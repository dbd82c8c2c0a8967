"""``lmm-studio eval-search``: motion search by example measured on a folder of takes (numpy, no torch):
the learned encoder, the classifier baseline and the plain features baseline side by side."""
from __future__ import annotations

import sys

from app.cli import number_in


def add_arguments(p) -> None:
    p.add_argument("--data", help="folder of BVH takes, labelled by their names' leading letters "
                                  "(default: the 27 shared LAFAN1 takes, ../shared/data/lafan1)")
    p.add_argument("--json", dest="json_path", help="write the report here as JSON")
    p.add_argument("--encoder", help="encoder weights (default: the shipped lmm/data/weights/search_encoder.npz)")
    p.add_argument("--classifier", help="classifier baseline weights (default: search_classifier.npz beside it)")
    p.add_argument("--queries-per-take", type=number_in(1, 1000, integer=True), default=24,
                   help="queries cut from each take's held-out part, 1..1000 (default 24)")


def main(args) -> int:
    from lmm.data.outputs import check_outputs
    from lmm.motion_search import encoder as enc
    from lmm.offline import search_eval as ev

    # everything the user named is checked before the minutes of embedding
    enc.load(args.encoder or enc.DEFAULT_WEIGHTS)
    enc.load(args.classifier or enc.CLASSIFIER_WEIGHTS)
    check_outputs([("--json", args.json_path)], [("--encoder", args.encoder), ("--classifier", args.classifier)])
    report = ev.evaluate(args.data, args.encoder, args.classifier,
                         ev.EvalSettings(queries_per_take=args.queries_per_take),
                         log=lambda msg: print(msg, file=sys.stderr))
    if args.json_path:
        from lmm.data.jsonio import write_json
        write_json(args.json_path, report)
    print(f"{report['n_queries']} held-out queries over {report['n_windows']} windows of {report['n_takes']} takes "
          f"({report['data']})")
    print(ev.format_table(report))
    return 0
