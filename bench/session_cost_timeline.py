"""The per-channel cost timeline of a reopened session (issue 33 item 4): how long its background job takes
for a long session, what it keeps, and what drawing it costs the GUI thread.

    PYTHONPATH=. python bench/session_cost_timeline.py [--minutes 10] [--controllers mm lmm]

For each controller a ``--minutes`` session is made by ``run --events`` on builtin:random:1 (bench/sessions.py's
36 tuning changes and 6 actions), then :func:`lmm.session.cost_timeline.session_cost_timeline` works out its
timeline as the studio's job does (opening the file, a replay on its own features copy). Prints the wall time
(and per tick), the bytes kept, the replay's fingerprint check, and the time to stack and thin one controller's
series for drawing (done once per timeline and controller on the GUI thread: app/panels/channel_costs.py).
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


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--minutes", type=float, default=10.0)
    p.add_argument("--controllers", nargs="+", default=["mm", "lmm"])
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for controller in a.controllers:
            measure(make_session(controller, a.minutes, Path(tmp)), controller)


if __name__ == "__main__":
    main()
