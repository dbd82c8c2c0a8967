"""The per-channel cost timeline of a session: made on a thread while the caller's features stay as they
are, equal to the trace's rows, and thinned for drawing without losing a spike."""
from __future__ import annotations

import threading

import numpy as np
import pytest


@pytest.fixture(scope="module")
def weighted_session(tmp_path_factory):
    """4 s of MM with the hip_velocity weight set to 3 at tick 90 (the replay rescales its features)."""
    import json

    from app.cli import main as cli_main

    folder = tmp_path_factory.mktemp("cost-timeline")
    events = folder / "events.json"
    events.write_text(json.dumps({"events": [{"tick": 90, "kind": "tuning", "payload": {
        "field": "feature_weights", "channel": "hip_velocity", "new": 3.0}}]}))
    path = folder / "s.lmmsession"
    assert cli_main(["run", "--controller", "mm", "--input", "builtin:random:1", "--seconds", "4", "--events",
                     str(events), "--session", str(path), "--quiet"]) == 0
    return path


def test_the_timeline_made_on_a_thread_equals_the_trace_and_leaves_the_features_alone(weighted_session):
    from app.commands.session_common import open_with_database
    from lmm.session.cost_timeline import session_cost_timeline
    from lmm.session.player import SessionPlayer
    from lmm.session.trace import columns, trace_rows

    session, db, features, _ = open_with_database(weighted_session)
    weights, normalized = features.weights.copy(), features.normalized
    out, progress = {}, []
    worker = threading.Thread(target=lambda: out.update(tl=session_cost_timeline(
        weighted_session, db, features, report=progress.append)))
    worker.start()
    worker.join()
    timeline = out["tl"]
    assert timeline.ticks == session.ticks == 240 and timeline.mismatches == 0 and progress
    assert np.array_equal(features.weights, weights) and features.normalized is normalized
    header = columns(features.names)
    for row in trace_rows(SessionPlayer(session, db, features), db, features):
        r = dict(zip(header, row))
        tick = r["tick"]
        assert timeline.costs["mm"][tick].tolist() == [np.float32(r[f"cost_{c}"]) for c in features.names], tick
        assert timeline.transitioned["mm"][tick] == r["transitioned"]
    assert timeline.transitioned["mm"].any()
    session.close()


def test_a_cancelled_timeline_is_none(weighted_session):
    from app.commands.session_common import open_with_database
    from lmm.session.cost_timeline import session_cost_timeline

    session, db, features, _ = open_with_database(weighted_session)
    session.close()
    assert session_cost_timeline(weighted_session, db, features, cancelled=lambda: True) is None


def test_stacked_bands_and_peak_rows():
    from lmm.session.cost_timeline import peak_rows, stacked

    costs = np.array([[1, 2], [np.nan, np.nan], [3, 0.5]], np.float32)
    s = stacked(costs)
    assert s[0].tolist() == [0, 1, 3] and np.isnan(s[1]).all() and s[2].tolist() == [0, 3, 3.5]
    total = np.zeros(1000)
    total[[17, 512, 998]] = [5.0, 9.0, 2.0]
    rows = peak_rows(total, 100)
    assert {17, 512, 998, 999} <= set(rows.tolist()) and len(rows) <= 101
    assert np.all(np.diff(rows) > 0)
    assert peak_rows(total[:50], 100).tolist() == list(range(50))
