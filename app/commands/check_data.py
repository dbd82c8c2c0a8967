"""``lmm-studio check-data``: what in a manifest's takes a motion matching database should not hold.

    lmm-studio check-data [--manifest M] [--json OUT] [--png OUT]

Checks every take over the whole file (calibration T-pose, airborne/climbing, contact sliding, speed and
turn outliers, frame rate and units; see :mod:`lmm.checks`), marks the findings that fall inside
ranges the manifest uses, and prints a coverage summary: seconds per tag and a root speed x turn-rate
table (``--png`` draws it). Frames are the file's own, ``[start, end)``. Exit status 0 even with findings;
1 when a file cannot be read (one ``error: ...`` line naming it).
"""
from __future__ import annotations

import sys


def add_arguments(p) -> None:
    p.add_argument("--manifest", help="dataset manifest (JSON or TOML); default: the shipped LAFAN1 locomotion set")
    p.add_argument("--json", metavar="OUT", help="write the findings and coverage here as JSON")
    p.add_argument("--png", metavar="OUT", help="draw the speed x turn-rate coverage as a PNG here")
    p.add_argument("--used-only", action="store_true", help="print only findings inside used ranges")
    p.add_argument("--quiet", action="store_true", help="print only the counts")


def main(args) -> int:
    from lmm import DEFAULT_MANIFEST
    from lmm.checks import CheckError, check_manifest, format_coverage
    from lmm.data.manifest import ManifestError, load_manifest

    from lmm.data.build import manifest_inputs
    from lmm.data.outputs import check_outputs

    manifest_path = args.manifest or DEFAULT_MANIFEST
    try:
        check_outputs([("--json", args.json), ("--png", args.png)], manifest_inputs(manifest_path))
        manifest = load_manifest(manifest_path)
        findings, coverage = check_manifest(manifest)
    except (ManifestError, CheckError) as e:
        print(f"lmm-studio check-data: error: {e}", file=sys.stderr)
        return 1
    used = [f for f in findings if f.in_used_range]
    if not args.quiet:
        for f in findings:
            if f.in_used_range or not args.used_only:
                print(f.line())
        print(format_coverage(coverage))
    print(f"{len(findings)} findings in {len(manifest.clips)} takes, {len(used)} inside used ranges")
    try:
        if args.json:
            from lmm.data.jsonio import write_json
            write_json(args.json, {"manifest": str(manifest_path), "findings": [f.to_dict() for f in findings],
                                   "coverage": coverage.to_dict()})
        if args.png:
            from lmm.reporting import draw_speed_turn_png
            draw_speed_turn_png(coverage.speed_turn, args.png,
                                title=f"seconds of used source motion by root speed x turn rate "
                                      f"({coverage.seconds_total:.0f} s in all)")
    except OSError as e:
        print(f"lmm-studio check-data: error: cannot write the output: {e}", file=sys.stderr)
        return 1
    return 0
