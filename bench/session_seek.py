"""Seeking in a reopened session (issue 33): how long showing a random tick takes, and the checkpoints' memory.

    PYTHONPATH=. python bench/session_seek.py [--minutes 10] [--long-minutes 30] [--controllers mm lmm]
                                              [--seeks 200] [--every 60] [--seed 0]

For each controller a ``--minutes`` session is made by ``run --events`` on builtin:random:1 (36 tuning
changes and 6 actions, bench/sessions.py's), opened with :class:`lmm.session.seek.SessionSeeker`, stepped
through once (the checkpoints, one every ``--every`` ticks), then ``--seeks`` random ticks are shown in a
random order: each is the seek plus what the studio's panels read of the tick's snapshot (the ghost
pose, trajectory and query). Prints the median and the distribution, and whether every pose with a recorded
fingerprint matched. Memory: the checkpoints' bytes and the process's peak RSS for a ``--long-minutes``
session (MM; 0 skips it).
"""
from __future__ import annotations

import argparse
import json
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from sessions import cli, events  # noqa: E402

LAZY = ("matched_pose_positions", "trajectory_positions", "trajectory_rotations", "query")


def make_session(controller: str, minutes: float, folder: Path) -> Path:
    seconds = minutes * 60
    ev = folder / f"events_{minutes:g}.json"
    ev.write_text(json.dumps(events(int(round(seconds * 60)))))
    out = folder / f"{controller}_{minutes:g}.lmmsession"
    r = cli("run", "--controller", controller, "--input", "builtin:random:1", "--seconds", seconds, "--events", ev,
            "--session", out, "--quiet")
    if r.returncode:
        raise SystemExit(f"run failed: {r.stderr.strip()}")
    return out


def open_seeker(path: Path, every: int):
    from app.commands.session_common import open_with_database
    from lmm.session.seek import SessionSeeker

    session, db, features, weights = open_with_database(path)
    return SessionSeeker(session, db, features, every=every, weights=weights)


def seek_times(path: Path, controller: str, n: int, every: int, rng) -> None:
    from lmm.session.schema import pose_fingerprint

    seeker = open_seeker(path, every)
    t0 = time.perf_counter()
    seeker.fill()
    fill_s = time.perf_counter() - t0
    times, checked, wrong = [], 0, 0
    for tick in rng.integers(0, seeker.ticks, n):
        t0 = time.perf_counter()
        poses, snaps = seeker.seek(int(tick))
        for name in LAZY:
            getattr(snaps[controller], name, None)
        times.append((time.perf_counter() - t0) * 1e3)
        recorded = seeker.session.fingerprints.get((int(tick), controller))
        if recorded is not None:
            checked += 1
            wrong += pose_fingerprint(poses[controller]) != recorded
    t = np.array(times)
    q = np.percentile(t, [10, 25, 50, 75, 90, 99])
    print(f"{controller}: {seeker.ticks} ticks, {len(seeker.checkpoints)} checkpoints every {every} ticks, "
          f"{seeker.checkpoint_bytes() / 2**20:.1f} MiB; first pass {fill_s:.1f} s")
    print(f"  show a random tick ({n}): median {q[2]:.1f} ms; p10 {q[0]:.1f}, p25 {q[1]:.1f}, p75 {q[3]:.1f}, "
          f"p90 {q[4]:.1f}, p99 {q[5]:.1f}, max {t.max():.1f} ms; {checked} fingerprinted ticks, {wrong} differ")


def long_memory(path: Path, every: int) -> None:
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    seeker = open_seeker(path, every)
    opened = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    seeker.fill()
    after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"long session: {seeker.ticks} ticks ({seeker.ticks / 3600:.0f} min), {len(seeker.checkpoints)} checkpoints, "
          f"{seeker.checkpoint_bytes() / 2**20:.1f} MiB of checkpoints; peak RSS {before:.0f} MiB before opening, "
          f"{opened:.0f} MiB opened, {after:.0f} MiB after the whole pass")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--minutes", type=float, default=10.0)
    p.add_argument("--long-minutes", type=float, default=30.0)
    p.add_argument("--controllers", nargs="+", default=["mm", "lmm"])
    p.add_argument("--seeks", type=int, default=200)
    p.add_argument("--every", type=int, default=60)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    rng = np.random.default_rng(a.seed)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if a.long_minutes > 0:
            long_memory(make_session("mm", a.long_minutes, folder), a.every)
        for controller in a.controllers:
            seek_times(make_session(controller, a.minutes, folder), controller, a.seeks, a.every, rng)


if __name__ == "__main__":
    main()
