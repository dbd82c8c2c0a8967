"""Seeking in a reopened session (issue 33): how long showing a random tick takes, and the checkpoints' memory.

    PYTHONPATH=. python bench/session_seek.py [--minutes 10] [--long-minutes 30] [--controllers mm lmm]
                                              [--seeks 200] [--every 60] [--seed 0] [--branch-at 10]

For each controller a ``--minutes`` session is made by ``run --events`` on builtin:random:1 (36 tuning
changes and 6 actions, bench/sessions.py's), opened with :class:`lmm.session.seek.SessionSeeker`, stepped
through once (the checkpoints, one every ``--every`` ticks), then ``--seeks`` random ticks are shown in a
random order: each is the seek plus what the studio's panels read of the tick's snapshot (the ghost
pose, trajectory and query). Prints the median and the distribution, and whether every pose with a recorded
fingerprint matched. Memory: the checkpoints' bytes and the process's peak RSS for a ``--long-minutes``
session (MM; 0 skips it). Branch here at the session's end (``--branch-at`` seconds before it, a preset
changing one feature weight): the time to B's first tick from A's nearest checkpoint
(:meth:`lmm.session.seek.SessionSeeker.branched`, what the studio does) against a branch replayed from the
session's start, and whether the two give the same poses for the next second.
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


def seek_times(seeker, controller: str, n: int, every: int, fill_s: float, rng) -> None:
    from lmm.session.schema import pose_fingerprint

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


def branch_start(seeker, controller: str, seconds_before_end: float) -> None:
    from lmm.session.seek import SessionSeeker

    branch = {"feature_weights": {"hip_velocity": 4.0}}
    tick = seeker.ticks - int(round(seconds_before_end * seeker.session.fps))
    seeker.seek(tick)                                       # the tick shown when Branch here is pressed
    t0 = time.perf_counter()
    b = seeker.branched(branch, tick)
    first = b.seek(tick)[0][controller].global_positions.copy()
    new_s, stepped = time.perf_counter() - t0, b.stepped
    t0 = time.perf_counter()
    replayed = SessionSeeker(seeker.session, seeker.db, seeker.features, weights=seeker.weights, branch=branch,
                             from_tick=tick)
    same = np.array_equal(first, replayed.seek(tick)[0][controller].global_positions)
    old_s = time.perf_counter() - t0
    for t in range(tick + 1, min(tick + 61, seeker.ticks)):
        same &= np.array_equal(b.seek(t)[0][controller].global_positions,
                               replayed.seek(t)[0][controller].global_positions)
    print(f"  branch here at tick {tick} of {seeker.ticks}: B's first tick {new_s * 1e3:.0f} ms from the checkpoint "
          f"({stepped} ticks stepped) against {old_s:.1f} s replayed from the start; the next second's poses "
          f"{'identical' if same else 'DIFFER'}")


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
    p.add_argument("--branch-at", type=float, default=10.0, help="Branch here this many seconds before the end")
    a = p.parse_args()
    rng = np.random.default_rng(a.seed)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if a.long_minutes > 0:
            long_memory(make_session("mm", a.long_minutes, folder), a.every)
        for controller in a.controllers:
            seeker = open_seeker(make_session(controller, a.minutes, folder), a.every)
            t0 = time.perf_counter()
            seeker.fill()
            fill_s = time.perf_counter() - t0
            if a.seeks > 0:
                seek_times(seeker, controller, a.seeks, a.every, fill_s, rng)
            branch_start(seeker, controller, a.branch_at)


if __name__ == "__main__":
    main()
