"""``lmm-studio input-from``: the controller input that makes a take's root path (see
:mod:`lmm.input_from_motion`).

    lmm-studio input-from FILE.bvh [--frames A:B] --out INPUT.csv [--manifest M] [--fps 60] [--json OUT]

Writes an input log (``run --input INPUT.csv`` replays it) and prints how closely the simulation object
driven by it follows the take's root: position error (cm) and facing error (degrees). The take is moved
to start at the origin facing +Z, as a controller starts. Frames are the file's own, ``[A, B)``.
"""
from __future__ import annotations

import argparse

from app.cli import number_in


def frame_range(text: str) -> tuple[int, int]:
    """``A:B`` (file frames, B exclusive) for argparse."""
    a, sep, b = text.partition(":")
    try:
        if not sep:
            raise ValueError
        return int(a), int(b)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected A:B (file frames, B exclusive), got {text[:40]!r}") from None


def add_arguments(p) -> None:
    p.add_argument("file", help="a BVH take (.bvh or .bvh.gz) with the manifest's skeleton")
    p.add_argument("--frames", type=frame_range, metavar="A:B", help="file frames A (inclusive) to B (exclusive)")
    p.add_argument("--out", required=True, metavar="INPUT.csv", help="the input log to write")
    p.add_argument("--manifest", help="manifest for the bone names, unit scale and root smoothing "
                                      "(default: the shipped one)")
    p.add_argument("--fps", type=number_in(1, 1000, unit="Hz"), default=60.0, help="ticks per second (default 60)")
    p.add_argument("--json", metavar="OUT", help="write the root path error here as JSON")


def main(args) -> int:
    from lmm import DEFAULT_MANIFEST
    from lmm.data.manifest import load_manifest
    from lmm.data.motion_files import load_motion
    from lmm.data.outputs import check_outputs
    from lmm.input_from_motion import derive_input, take_root_path, write_input_csv

    check_outputs([("--out", args.out), ("--json", args.json)],
                  [("FILE", args.file), ("--manifest", args.manifest or DEFAULT_MANIFEST)])
    manifest = load_manifest(args.manifest or DEFAULT_MANIFEST)
    anim = load_motion(args.file)
    root = take_root_path(anim, manifest, str(args.file), args.frames)
    derived = derive_input(root, dt=1.0 / args.fps)
    write_input_csv(derived, args.out)
    e = derived.path_error()
    a, b = root.frames
    print(f"{args.file} [{a}:{b}]: {e['seconds']:.1f} s, {e['ticks']} ticks -> {args.out}")
    print(f"root path of the replayed input against the take: position mean {e['position_mean_m'] * 100:.1f} cm, "
          f"95% {e['position_p95_m'] * 100:.1f} cm, max {e['position_max_m'] * 100:.1f} cm; facing mean "
          f"{e['yaw_mean_deg']:.1f} deg, max {e['yaw_max_deg']:.0f} deg; faster than the controller's speeds "
          f"{e['clamped_fraction'] * 100:.1f} % of ticks")
    if args.json:
        from lmm.data.jsonio import write_json
        write_json(args.json, {"file": str(args.file), "frames": [a, b], "fps": args.fps, "input": str(args.out),
                               "root_path_error": e})
    return 0
