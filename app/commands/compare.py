"""``lmm-studio compare``: how far apart two motions of the same skeleton are, after dynamic time warping
(see :mod:`lmm.compare`).

    lmm-studio compare A.bvh B.bvh [--frames-a A:B] [--frames-b A:B] [--window N] [--json OUT]

Prints the rotation error (radians, mean geodesic angle over joints and aligned frames) and the position
error (cm, root-relative and world); the world error is taken with B's start moved onto A's (same ground
position and facing at the first aligned frames; ``--no-align``: as the files place them); ``--json``
adds the per-frame errors and the alignment path.
"""
from __future__ import annotations

from app.cli import number_in
from app.commands.input_from import frame_range


def add_arguments(p) -> None:
    p.add_argument("a", help="the reference motion (BVH)")
    p.add_argument("b", help="the motion compared with it (BVH, same skeleton; a recording's simulation bone "
                             "is ignored)")
    p.add_argument("--frames-a", type=frame_range, metavar="A:B", help="file frames of the first motion")
    p.add_argument("--frames-b", type=frame_range, metavar="A:B", help="file frames of the second motion")
    p.add_argument("--window", type=number_in(1, 10**7, integer=True), default=None,
                   help="Sakoe-Chiba half-width in frames (default: a tenth of the longer motion, at least 10)")
    p.add_argument("--cm-per-unit", type=number_in(1e-4, 1e4), default=1.0,
                   help="centimetres per file unit (default 1: LAFAN1 and recordings are in cm)")
    p.add_argument("--no-align", dest="align", action="store_false",
                   help="world error as the files place the motions (default: B's start moved to A's ground "
                        "position and facing)")
    p.add_argument("--json", metavar="OUT", help="write the errors, per-frame errors and the path here")


def main(args) -> int:
    from lmm.compare import compare_files
    from lmm.data.outputs import check_outputs

    check_outputs([("--json", args.json)], [("A", args.a), ("B", args.b)])
    r = compare_files(args.a, args.b, args.frames_a, args.frames_b, args.window, args.cm_per_unit,
                      align_start=args.align)
    n, m = r["frames"]
    print(f"{args.a} ({n} frames) vs {args.b} ({m} frames), {r['joints']} joints, window {r['window']}: "
          f"rotation {r['rotation_error_rad']:.4f} rad, position {r['position_error_cm']['root_relative']:.2f} cm "
          f"root-relative, {r['position_error_cm']['world']:.2f} cm world "
          f"({'starts aligned' if args.align else 'not aligned'}; {len(r['path'])} aligned pairs)")
    if args.json:
        from lmm.data.jsonio import write_json
        write_json(args.json, r)
    return 0
