"""The studio's channel cost timeline job: the child process gives the timeline an in-process replay
gives, and a cancelled job stops its child."""
from __future__ import annotations

import time

import numpy as np
import pytest


class _Job:
    def __init__(self, cancel_after: float | None = None):
        self.start, self.cancel_after, self.reports = time.monotonic(), cancel_after, []

    @property
    def cancelled(self) -> bool:
        return self.cancel_after is not None and time.monotonic() - self.start > self.cancel_after

    def report(self, fraction):
        self.reports.append(fraction)


@pytest.fixture(scope="module")
def session_path(tmp_path_factory):
    from app.cli import main as cli_main

    path = tmp_path_factory.mktemp("cost-job") / "s.lmmsession"
    assert cli_main(["run", "--controller", "mm", "--input", "builtin:random:1", "--seconds", "12",
                     "--session", str(path), "--quiet"]) == 0
    return path


def test_the_child_gives_the_in_process_timeline(session_path):
    from app.commands.session_common import open_with_database
    from app.cost_timeline_job import compute_in_child
    from lmm.session.cost_timeline import session_cost_timeline

    job = _Job()
    child = compute_in_child(job, session_path)
    session, db, features, _ = open_with_database(session_path)
    session.close()
    here = session_cost_timeline(session_path, db, features)
    assert (child.channels, child.dt, child.mismatches, child.ticks) == (here.channels, here.dt, 0, 720)
    assert np.array_equal(child.costs["mm"], here.costs["mm"])
    assert np.array_equal(child.transitioned["mm"], here.transitioned["mm"])
    assert job.reports and all(0 <= f < 1 for f in job.reports)


def test_a_cancelled_job_returns_none_and_stops_its_child(session_path, monkeypatch):
    import subprocess

    from app.cost_timeline_job import compute_in_child

    started = []
    popen = subprocess.Popen

    def keep(*a, **kw):
        started.append(popen(*a, **kw))
        return started[-1]

    monkeypatch.setattr(subprocess, "Popen", keep)
    assert compute_in_child(_Job(cancel_after=0.0), session_path) is None
    assert started and started[0].poll() is not None
