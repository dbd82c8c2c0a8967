"""kill -9 and SIGTERM during ``build-db`` of the full LAFAN1 set (issue 36's acceptance): after each kill the
next build succeeds, the cache and ``$TMPDIR`` hold no debris, and no traceback reaches the terminal.

    LAFAN1_DIR=../shared/data/lafan1 PYTHONPATH=. python bench/build_kills.py [--kills 20] [--seed 36]

Runs in a private ``$TMPDIR`` and ``LMM_STUDIO_CACHE``, with the tree this script is in (run a copy,
``git archive HEAD | tar -x -C DIR``, where others edit the working tree: a half-edited module is an
internal error no kill caused). One timed good build first (its wall time bounds the
random moments); then ``--kills`` times: ``build-db --rebuild`` of lafan1_full.json, SIGKILL or SIGTERM
(alternating) at a uniformly random moment of the last good build's span (a build that ended first: rc 0), wait for every process of the build to end, note
what is left, then a full build that must exit 0 and leave nothing. Prints one line per kill and a JSON summary.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from lmm.data.leftovers import processes_using_tmpdir  # noqa: E402

MANIFEST = ROOT / "lmm" / "data" / "manifests" / "lafan1_full.json"


#: where app/cli.py writes the report of an internal error (exit 70): a failure, but not debris
CRASH_REPORTS = "lmm-studio-logs"


def crash_reports(tmp: Path) -> list[str]:
    """The last line of each internal-error report in $TMPDIR, which are then removed (so each kill is
    judged on its own)."""
    import shutil

    folder = tmp / CRASH_REPORTS
    lines = [(f.read_text(errors="replace").strip().splitlines() or [""])[-1] for f in sorted(folder.glob("*"))]
    shutil.rmtree(folder, ignore_errors=True)
    return lines


def debris(tmp: Path, cache: Path) -> list[str]:
    """Everything in the private $TMPDIR (but crash reports), and the cache's temporaries."""
    found = [f"TMPDIR/{p.name}" for p in tmp.iterdir() if p.name != CRASH_REPORTS]
    found += [f"cache/{p.relative_to(cache)}" for p in cache.rglob("*")
              if p.name.endswith((".tmp", ".probe", ".partial", ".saving"))] if cache.exists() else []
    return found


def build(cmd, env, timeout=1800) -> tuple[int, str, float]:
    t0 = time.perf_counter()
    r = subprocess.run(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                       timeout=timeout)
    return r.returncode, r.stderr, time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--seed", type=int, default=36)
    ap.add_argument("--json", help="write the summary here too")
    args = ap.parse_args(argv)
    if not os.environ.get("LAFAN1_DIR"):
        print("set LAFAN1_DIR to the folder holding the LAFAN1 .bvh files", file=sys.stderr)
        return 2
    work = Path(tempfile.mkdtemp(prefix="lmm-build-kills-"))
    tmp, cache = work / "tmp", work / "cache"
    tmp.mkdir()
    env = {**os.environ, "TMPDIR": str(tmp), "LMM_STUDIO_CACHE": str(cache), "PYTHONPATH": str(ROOT),
           "LAFAN1_DIR": str(Path(os.environ["LAFAN1_DIR"]).resolve())}
    cmd = [sys.executable, "-m", "app.cli", "build-db", "--manifest", str(MANIFEST), "--rebuild", "--quiet"]
    rc, err, span = build(cmd, env)
    if rc != 0:
        print(f"the first build failed (rc {rc}):\n{err}", file=sys.stderr)
        return 1
    print(f"good build: {span:.1f} s; kills at random moments in 0..{span:.1f} s", flush=True)
    rng = random.Random(args.seed)
    rows, failures = [], 0
    for i in range(args.kills):
        sig = (signal.SIGKILL, signal.SIGTERM)[i % 2]
        delay = rng.uniform(0.0, span)   # span: the last good build's wall time (the machine's load changes)
        p = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        time.sleep(delay)
        p.send_signal(sig)
        _, kill_err = p.communicate(timeout=300)
        deadline = time.monotonic() + 30
        while processes_using_tmpdir(tmp) and time.monotonic() < deadline:
            time.sleep(0.1)
        survivors = processes_using_tmpdir(tmp)
        left_after_kill = debris(tmp, cache)
        rc2, err2, wall2 = build(cmd, env)
        span = wall2 if rc2 == 0 else span
        left = debris(tmp, cache)
        crashes = crash_reports(tmp)
        row = {"kill": i + 1, "signal": sig.name, "at_s": round(delay, 2), "rc": p.returncode,
               "traceback": "Traceback" in kill_err or "Traceback" in err2, "workers_left": len(survivors),
               "left_after_kill": len(left_after_kill), "next_build_rc": rc2, "next_build_s": round(wall2, 1),
               "debris_after_next_build": left, "internal_errors": crashes}
        ok = (rc2 == 0 and not row["traceback"] and not left and not survivors and not crashes
              and (sig != signal.SIGTERM or p.returncode in (0, 143)))
        failures += not ok
        row["ok"] = ok
        rows.append(row)
        print(f"{i + 1:2d} {sig.name:7s} at {delay:5.2f} s: rc {p.returncode}, {len(left_after_kill)} left after the "
              f"kill, next build rc {rc2} in {wall2:.1f} s, debris {left or 'none'}, workers left {len(survivors)}"
              f"{', TRACEBACK' if row['traceback'] else ''}{f', internal error: {crashes}' if crashes else ''}"
              f" -> {'ok' if ok else 'FAIL'}", flush=True)
        if row["traceback"]:
            print(kill_err[-2000:] + err2[-2000:], flush=True)
    summary = {"kills": args.kills, "seed": args.seed, "good_build_s": round(span, 1), "failures": failures,
               "rows": rows}
    print(json.dumps({k: v for k, v in summary.items() if k != "rows"}))
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=2))
    import shutil
    shutil.rmtree(work, ignore_errors=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
