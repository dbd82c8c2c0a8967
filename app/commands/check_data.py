"""``lmm-studio check-data``: what in a manifest's takes a motion matching database should not hold.

    lmm-studio check-data [--manifest M] [--json OUT] [--png OUT]

Checks every take over the whole file (calibration T-pose, airborne/climbing, contact sliding, speed and
turn outliers, frame rate and units; see :mod:`lmm.checks`), marks the findings that fall inside
ranges the manifest uses, and prints a summary a terminal holds: the findings inside used ranges (up to
:data:`LISTED_FINDINGS`), a count per kind of the others, the seconds per tag and how much of the root
speed x turn-rate table holds motion. ``--verbose`` lists every finding and prints the table (``--png``
draws it, ``--json`` holds it all). Frames are the file's own, ``[start, end)``. Exit status 0 even with
findings; 1 when a file cannot be read (one ``error: ...`` line naming it).
"""
from __future__ import annotations

import sys


def add_arguments(p) -> None:
    p.add_argument("--manifest", help="dataset manifest (JSON or TOML); default: the shipped LAFAN1 locomotion set")
    p.add_argument("--json", metavar="OUT", help="write the findings and coverage here as JSON")
    p.add_argument("--png", metavar="OUT", help="draw the speed x turn-rate coverage as a PNG here")
    p.add_argument("--used-only", action="store_true", help="list and count only findings inside used ranges")
    talk = p.add_mutually_exclusive_group()
    talk.add_argument("--quiet", action="store_true", help="print only the counts")
    talk.add_argument("--verbose", action="store_true",
                      help="list every finding and print the speed x turn-rate table (default: a summary)")


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
    if args.verbose:
        for f in findings:
            if f.in_used_range or not args.used_only:
                print(f.line())
        print(format_coverage(coverage))
    elif not args.quiet:
        print(summary_text(used, [] if args.used_only else [f for f in findings if not f.in_used_range], coverage))
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


#: findings inside used ranges listed by default (each is motion the database plays); the rest are counted
LISTED_FINDINGS = 10


def summary_text(used: list, others: list, coverage) -> str:
    """The default output: the used-range findings (the first :data:`LISTED_FINDINGS`, the rest counted
    per kind), a count per kind of ``others``, the seconds per tag on one line and the share of speed x
    turn cells holding motion."""
    lines = [f.line() for f in used[:LISTED_FINDINGS]]
    if len(used) > LISTED_FINDINGS:
        rest = used[LISTED_FINDINGS:]
        lines.append(f"... {len(rest)} more inside used ranges: {kind_counts(rest)} (--verbose lists them)")
    if others:
        lines.append(f"outside used ranges: {kind_counts(others)} (--verbose lists them)")
    tags = ", ".join(f"{tag} {sec:.1f} s" for tag, sec in coverage.seconds_per_tag.items())
    lines.append(f"coverage: {coverage.seconds_total:.1f} s of source motion in used ranges (x2 when mirrored)"
                 + (f"; {tags}" if tags else ""))
    held = coverage.speed_turn.seconds > 0
    speeds = coverage.speed_turn.speed_edges_m_s
    rows = held.any(axis=1).nonzero()[0]
    top = f", up to {speeds[rows.max() + 1]:g} m/s" if rows.size else ""
    lines.append(f"speed x turn rate: {int(held.sum())} of {held.size} cells hold motion{top} "
                 f"(--verbose prints the table, --png draws it)")
    return "\n".join(lines)


def kind_counts(findings: list) -> str:
    """``12 airborne, 3 contact_sliding``: how many findings of each kind, most first."""
    kinds: dict[str, int] = {}
    for f in findings:
        kinds[f.kind] = kinds.get(f.kind, 0) + 1
    return ", ".join(f"{n} {kind}" for kind, n in sorted(kinds.items(), key=lambda kv: -kv[1]))
