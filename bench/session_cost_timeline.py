"""The per-channel cost timeline of a reopened session (issue 33 item 4): how long its background job takes
for a long session, what it keeps, and what drawing it costs the GUI thread.

    PYTHONPATH=. python bench/session_cost_timeline.py [--minutes 10] [--controllers mm lmm] [--seeks 150]

For each controller a ``--minutes`` session is made by ``run --events`` on builtin:random:1 (bench/sessions.py's
36 tuning changes and 6 actions), then :func:`lmm.session.cost_timeline.session_cost_timeline` works out its
timeline as the studio's job does (opening the file, a replay on its own features copy). Prints the wall time
(and per tick), the bytes kept, the replay's fingerprint check, and the time to stack and thin one controller's
series for drawing (done once per timeline and controller on the GUI thread: app/panels/channel_costs.py).
Then what the job costs a studio showing the same session: ``--seeks`` random ticks shown (seek and query, as
bench/session_seek.py) alone, while the job runs on a thread, and while it runs in a child process (the
studio's way: app/cost_timeline_job.py); medians and p90.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from session_seek import make_session  # noqa: E402


def measure(path: Path, controller: str) -> None:
    from app.commands.session_common import open_with_database
    from app.panels.channel_costs import MAX_POINTS
    from lmm.session.cost_timeline import peak_rows, session_cost_timeline, stacked

    session, db, features, weights = open_with_database(path)
    ticks = session.ticks
    session.close()
    t0 = time.perf_counter()
    timeline = session_cost_timeline(path, db, features, weights=weights)
    job_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    stack = stacked(timeline.costs[controller])
    rows = peak_rows(stack[:, -1], MAX_POINTS)
    draw_ms = (time.perf_counter() - t0) * 1e3
    jumps = int(np.count_nonzero(timeline.transitioned[controller]))
    print(f"{controller}: {ticks} ticks ({ticks / 3600:.0f} min): timeline job {job_s:.1f} s "
          f"({job_s / ticks * 1e6:.0f} us a tick), {timeline.nbytes() / 2**20:.2f} MiB kept, "
          f"{timeline.mismatches} fingerprint mismatches; {jumps} transitions; stacking and thinning to "
          f"{len(rows)} points {draw_ms:.1f} ms")


def seek_ms(seeker, controller: str, n: int, rng) -> tuple[float, float]:
    times = []
    for tick in rng.integers(0, seeker.ticks, n):
        t0 = time.perf_counter()
        getattr(seeker.seek(int(tick))[1][controller], "query")
        times.append((time.perf_counter() - t0) * 1e3)
    return float(np.median(times)), float(np.percentile(times, 90))


def contention(path: Path, controller: str, n: int) -> None:
    import threading

    from app.commands.session_common import open_with_database
    from app.cost_timeline_job import compute_in_child
    from app.jobs import Jobs
    from lmm.session.cost_timeline import session_cost_timeline
    from session_seek import open_seeker

    seeker = open_seeker(path, 60)
    seeker.fill()
    rng = np.random.default_rng(0)
    rows = [("alone", seek_ms(seeker, controller, n, rng))]
    session, db, features, weights = open_with_database(path)
    session.close()
    thread = threading.Thread(target=lambda: session_cost_timeline(path, db, features, weights=weights))
    thread.start()
    time.sleep(1.0)
    rows.append(("job on a thread", seek_ms(seeker, controller, n, rng)))
    thread.join()
    job = Jobs().submit("cost-timeline", lambda job: compute_in_child(job, path))
    time.sleep(1.0)
    rows.append(("job in a child process", seek_ms(seeker, controller, n, rng)))
    job.wait()
    print(f"  showing a random tick ({n}): " + "; ".join(f"{label} median {m:.1f} ms, p90 {q:.1f} ms"
                                                        for label, (m, q) in rows))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--minutes", type=float, default=10.0)
    p.add_argument("--controllers", nargs="+", default=["mm", "lmm"])
    p.add_argument("--seeks", type=int, default=150, help="random ticks shown per case (0: no contention rows)")
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for controller in a.controllers:
            path = make_session(controller, a.minutes, Path(tmp))
            measure(path, controller)
            if a.seeks:
                contention(path, controller, a.seeks)


if __name__ == "__main__":
    main()
