"""A reopened session's channel cost timeline, worked out in a child process (``python -m
app.cost_timeline_job SESSION OUT.npz [--manifest M]``) that a studio job waits on.

The timeline replays the whole session (:func:`lmm.session.cost_timeline.session_cost_timeline`: 22 s for
10 minutes of MM, 50 s of LMM; ``bench/session_cost_timeline.py``). On a thread of the studio it would share
the interpreter lock with the GUI thread; in a child it competes for a core only. Measured on a 2-core
machine busy with other work (so the cores, not the lock, were scarce): showing a random tick of a reopened
10-minute MM session took 21 ms median (p90 40) alone, 47 ms (p90 103) with the job on a thread and 45 ms
(p90 74) with it in a child process (load average 5.5-6). The child loads the database from its cache
(about a second), replays, and writes the timeline as arrays; it says its progress on stdout and stops when
the studio goes (its parent changes) or the job is cancelled (it is killed).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def compute_in_child(job, session_path, manifest_path=None):
    """For a :class:`app.jobs.Job`: run the child, relay its progress, return the
    :class:`lmm.session.cost_timeline.CostTimeline` (None when the job was cancelled)."""
    with tempfile.TemporaryDirectory(prefix="lmm-cost-timeline-") as tmp:
        out = Path(tmp) / "timeline.npz"
        cmd = [sys.executable, "-m", "app.cost_timeline_job", str(session_path), str(out)]
        if manifest_path:
            cmd += ["--manifest", str(manifest_path)]
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(Path(__file__).resolve().parents[1]),
                                                            os.environ.get("PYTHONPATH", "")]))
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        try:
            for line in proc.stdout:
                if job.cancelled:
                    return None
                if line.startswith("progress "):
                    job.report(float(line.split()[1]))
            err = proc.stderr.read()
            if proc.wait() != 0:
                raise RuntimeError((err.strip().splitlines() or ["the child process failed"])[-1])
            return load(out)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()


def save(path, timeline) -> None:
    names = list(timeline.costs)
    np.savez(path, channels=np.array(timeline.channels), controllers=np.array(names), dt=timeline.dt,
             mismatches=timeline.mismatches, **{f"costs_{i}": timeline.costs[n] for i, n in enumerate(names)},
             **{f"jumps_{i}": timeline.transitioned[n] for i, n in enumerate(names)})


def load(path):
    from lmm.session.cost_timeline import CostTimeline

    with np.load(path) as z:
        names = [str(n) for n in z["controllers"]]
        return CostTimeline([str(c) for c in z["channels"]], float(z["dt"]),
                            {n: z[f"costs_{i}"] for i, n in enumerate(names)},
                            {n: z[f"jumps_{i}"] for i, n in enumerate(names)}, int(z["mismatches"]))


def main(argv=None) -> int:
    from app.commands.session_common import open_with_database
    from lmm.session.cost_timeline import session_cost_timeline

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("session")
    p.add_argument("out")
    p.add_argument("--manifest")
    a = p.parse_args(argv)
    parent = os.getppid()
    session, db, features, weights = open_with_database(a.session, a.manifest)
    session.close()
    timeline = session_cost_timeline(a.session, db, features, weights=weights,
                                     report=lambda f: print(f"progress {f:.4f}", flush=True),
                                     cancelled=lambda: os.getppid() != parent)
    if timeline is None:
        return 1
    save(a.out, timeline)
    return 0


if __name__ == "__main__":
    sys.exit(main())
