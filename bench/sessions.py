"""Sessions (issue 33): kill -9 of ``run --session`` at random moments, and a long session replayed exactly.

    PYTHONPATH=. python bench/sessions.py [--kills 20] [--minutes 10] [--controllers mm lmm] [--seed 0]

Kills: ``lmm-studio run --session --realtime`` is SIGKILLed ``--kills`` times at random moments (a quarter of
them within the first 0.5 s); each file left behind must open and replay to its last committed tick (or not
exist). Long: a ``--minutes`` session per controller on builtin:random:1 with 36 tuning changes and 6 actions
from ``--events``, recorded, then ``replay --record``: the two BVH files are compared byte for byte and the
session's size, the run's and the replay's wall times are printed.
"""
from __future__ import annotations

import argparse
import filecmp
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


def cli(*argv, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "app.cli", *map(str, argv)], cwd=ROOT, capture_output=True,
                          text=True, env={**os.environ, "PYTHONPATH": str(ROOT)}, **kw)


def kills(n: int, folder: Path, rng: random.Random) -> None:
    from lmm.session.reader import open_session

    early = max(1, n // 4)
    delays = [rng.uniform(0.0, 0.5) for _ in range(early)] + [rng.uniform(0.5, 6.0) for _ in range(n - early)]
    rows = []
    for i, delay in enumerate(delays):
        out = folder / f"kill{i:02d}.lmmsession"
        p = subprocess.Popen([sys.executable, "-m", "app.cli", "run", "--input", "builtin:random:1", "--seconds", "60",
                              "--realtime", "--session", str(out), "--quiet"], cwd=ROOT,
                             env={**os.environ, "PYTHONPATH": str(ROOT)})
        time.sleep(delay)
        p.send_signal(signal.SIGKILL)
        p.wait()
        if not out.exists():
            rows.append((delay, "no file", "-"))
            continue
        try:
            ticks = open_session(out).ticks
        except Exception as e:  # noqa: BLE001 - the finding
            rows.append((delay, f"DOES NOT OPEN: {e}", "-"))
            continue
        r = cli("replay", out)
        ok = r.returncode == 0 and f"replayed {ticks} ticks" in r.stdout
        rows.append((delay, f"{ticks} ticks committed", "replays, fingerprints match" if ok else
                     f"REPLAY FAILED: {(r.stderr or r.stdout).strip()[:200]}"))
    print(f"kill -9 of run --session, {n} times:")
    for delay, state, replay in sorted(rows):
        print(f"  {delay:6.3f} s  {state:<22} {replay}")
    bad = [r for r in rows if "FAILED" in r[2] or "NOT OPEN" in r[1]]
    print(f"  {n - len(bad)} of {n} left no file or a session that replays ({sum(r[1] == 'no file' for r in rows)} "
          f"without a file)")


def events(n_ticks: int) -> dict:
    """36 tuning changes and 6 actions spread over ``n_ticks``."""
    # every value differs from the one before it (the defaults first), so each is a recorded change
    values = [("search_interval_s", None, (0.05, 0.1, 0.2)), ("transition_cost", None, (0.3, 0.5, 0.2)),
              ("feature_weights", "left_foot_position", (1.2, 1.5, 1.0)), ("tag_bias", "run", (-0.2, -0.3, 0.3)),
              ("inertialization_halflife_s", None, (0.12, 0.15, 0.05)), ("stick_deadzone", None, (0.22, 0.3, 0.25)),
              ("ik_enabled", None, (False, True, False)), ("exclude_current_window_frames", None, (25, 30, 10)),
              ("feature_weights", "trajectory_direction", (1.7, 2.0, 1.0)), ("run_forward_speed_m_s", None, (3.0, 3.4, 2.5)),
              ("clamp_max_distance_m", None, (0.2, 0.1, 0.12)), ("idle_delay_s", None, (1.0, 0.5, 0.7))]
    changes = [(f, c, v[k]) for k in range(3) for f, c, v in values]
    out = []
    step = n_ticks // (len(changes) + 1)
    for i, (field, channel, value) in enumerate(changes):
        payload = {"field": field, "new": value, **({"channel": channel} if channel else {})}
        out.append({"tick": (i + 1) * step, "kind": "tuning", "payload": payload})
    for i, (kind, payload) in enumerate([("reset", {}), ("teleport", {"position": [3.0, 0.0, 1.0], "yaw_deg": 90.0}),
                                         ("reset", {"position": [0.0, 0.0, -2.0]}), ("command", {"id": "camera_follow"}),
                                         ("teleport", {"position": [-2.0, 0.0, 0.0]}), ("reset", {})]):
        out.append({"tick": (2 * i + 1) * n_ticks // 13, "kind": kind, "payload": payload})
    return {"events": sorted(out, key=lambda e: e["tick"])}


def long_session(controller: str, minutes: float, folder: Path) -> None:
    seconds = minutes * 60
    ev = folder / "events.json"
    ev.write_text(json.dumps(events(int(round(seconds * 60)))))
    session, bvh, again = (folder / f"{controller}.lmmsession", folder / f"{controller}.bvh",
                           folder / f"{controller}.replay.bvh")
    t0 = time.perf_counter()
    r = cli("run", "--controller", controller, "--input", "builtin:random:1", "--seconds", seconds, "--events", ev,
            "--session", session, "--record", bvh, "--quiet")
    run_s = time.perf_counter() - t0
    if r.returncode:
        print(f"{controller}: run failed: {r.stderr.strip()}")
        return
    t0 = time.perf_counter()
    r = cli("replay", session, "--record", again)
    replay_s = time.perf_counter() - t0
    same = filecmp.cmp(bvh, again, shallow=False)
    import sqlite3
    con = sqlite3.connect(session)
    counts = {t: con.execute(f"SELECT count(*) FROM {t}").fetchone()[0] for t in ("inputs", "events", "fingerprints")}
    kinds = dict(con.execute("SELECT kind, count(*) FROM events GROUP BY kind").fetchall())
    con.close()
    print(f"{controller}, {minutes:g} min ({int(seconds * 60)} ticks): session {session.stat().st_size / 1024:.0f} KiB "
          f"(rows: {counts}; events {kinds}); run {run_s:.1f} s, replay {replay_s:.1f} s (both with process start "
          f"and database load); replay: {r.stdout.strip() or r.stderr.strip()}; BVH {bvh.stat().st_size / 2**20:.1f} MiB, "
          f"cmp {'IDENTICAL' if same else 'DIFFERENT'}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--controllers", nargs="*", default=["mm", "lmm"])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_sessions_") as tmp:
        if args.kills:
            kills(args.kills, Path(tmp), random.Random(args.seed))
        for controller in args.controllers:
            long_session(controller, args.minutes, Path(tmp))


if __name__ == "__main__":
    main()
