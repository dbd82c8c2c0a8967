"""The bad-input corpus as a table: files x commands and each case's outcome (tests/test_corpus.py runs
the same cases and asserts them).

    python bench/corpus_report.py [--json OUT] [-k SUBSTRING ...] [--workers 2]

Prints the counts (files, commands, cases per kind), one line per failing case grouped by cause, the
slowest and most memory-hungry cases, per-job wall times, and the total; ``--json`` writes everything.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
import time
from collections import Counter, defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "corpus"))
sys.path.insert(0, str(ROOT / "tests"))
# the repository first: with tests/ ahead of it, tests/lmm (no __init__) was taken for the package lmm
# under an editable install's finder, and the recording check's `from lmm.data import bvh` failed
sys.path.insert(0, str(ROOT))

import corpus_cases as cc  # noqa: E402
from corpus_harness import run_jobs  # noqa: E402


def cause_of(problem: str) -> str:
    """A short grouping key for a problem line."""
    if problem.startswith("traceback: "):
        return "traceback " + problem[len("traceback: "):].split(":")[0]
    if problem.startswith("accepted"):
        return "accepted (exit 0)"
    if problem.startswith("still running"):
        return "timeout (killed at 30 s)"
    if problem.startswith("peak resident memory"):
        return "memory > 1 GiB"
    if problem.startswith("exit "):
        return re.sub(r"; stderr.*", "", problem)
    if problem.startswith("stderr has"):
        return "stderr not one line"
    if problem.startswith("the error does not name the field"):
        return "field not named"
    if problem.startswith("the error does not name"):
        return "file not named"
    return problem.split(":")[0][:60]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", help="write the cases and outcomes here")
    ap.add_argument("-k", action="append", default=[], help="only cases whose id holds this (repeatable)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    from test_corpus import _recording_left_behind, problems

    cases = [c for c in cc.case_table() if not args.k or any(k in c.id for k in args.k)]
    tmp = Path(tempfile.mkdtemp(prefix="corpus-report-"))
    t0 = time.perf_counter()
    targets, mounts = cc.make_targets(tmp)
    try:
        jobs, skipped = cc.build_jobs(cases, tmp, targets)
        t_gen = time.perf_counter() - t0
        results, metas = run_jobs(jobs, workers=args.workers)
        rows = []
        for c in cases:
            if c.id in skipped:
                rows.append({"id": c.id, "kind": c.kind, "command": c.command, "outcome": "skipped",
                             "problems": [skipped[c.id]]})
                continue
            r = results.get(c.id, {})
            found = problems(c, r) if r else ["no result"]
            if c.recording:
                found += _recording_left_behind(c, targets)
            rows.append({"id": c.id, "kind": c.kind, "command": c.command, "file": c.file, "what": c.what,
                         "outcome": "pass" if not found else "FAIL", "problems": found,
                         "rc": r.get("rc"), "seconds": r.get("seconds"), "maxrss_mib": (r.get("maxrss") or 0) / 2**20,
                         "stderr_head": (r.get("stderr") or "")[:300], "job": r.get("job")})
    finally:
        cc.unmount(mounts)
        import shutil
        shutil.rmtree(tmp, ignore_errors=True)  # the generated files are ~160 MB
    total = time.perf_counter() - t0

    files = {(c.kind, c.file) for c in cases if c.kind not in ("args", "target", "control")}
    print("corpus: files x commands")
    print(f"{'kind':<10} {'files':>5} {'commands':<40} {'cases':>5} {'pass':>5} {'FAIL':>5} {'skip':>5}")
    by_kind = defaultdict(list)
    for row in rows:
        by_kind[row["kind"]].append(row)
    for kind, krows in by_kind.items():
        nfiles = len({r["file"] for r in krows if "file" in r}) if kind not in ("args", "target") else len(krows)
        cmds = sorted({r["command"] for r in krows})
        n = Counter(r["outcome"] for r in krows)
        print(f"{kind:<10} {nfiles:>5} {','.join(cmds):<40} {len(krows):>5} {n['pass']:>5} {n['FAIL']:>5} "
              f"{n['skipped']:>5}")
    n = Counter(r["outcome"] for r in rows)
    print(f"{'total':<10} {len(files):>5} {'':<40} {len(rows):>5} {n['pass']:>5} {n['FAIL']:>5} {n['skipped']:>5}")

    groups = defaultdict(list)
    for row in rows:
        if row["outcome"] == "FAIL":
            groups[cause_of(row["problems"][0])].append(row)
    if groups:
        print("\nfailing cases by cause (first problem of each):")
        for cause, grows in sorted(groups.items(), key=lambda kv: -len(kv[1])):
            print(f"\n  {cause} ({len(grows)})")
            for row in grows:
                print(f"    {row['id']}: {'; '.join(row['problems'])[:220]}")
    timed = [r for r in rows if r.get("seconds") is not None]
    print("\nslowest cases:")
    for r in sorted(timed, key=lambda r: -r["seconds"])[:8]:
        print(f"  {r['seconds']:6.2f} s  {r['maxrss_mib']:6.0f} MiB  {r['id']}")
    print("\njobs (wall s):", ", ".join(f"{m['job']} {m['seconds']:.1f}" for m in sorted(metas, key=lambda m: -m["seconds"])[:10]))
    print(f"\ngenerating files {t_gen:.1f} s; whole corpus {total:.1f} s wall with {args.workers} workers")
    if args.json:
        Path(args.json).write_text(json.dumps({"seconds": total, "generate_seconds": t_gen, "cases": rows,
                                               "jobs": metas}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
