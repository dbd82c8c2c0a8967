"""The per-channel cost timeline of a reopened session (the Nearest Neighbour vs Projector panel's "channel
costs" tab), in one studio run under Xvfb: a ``run --session`` with a feature weight changed mid-session is
reopened with ``--open``; the timeline covers every tick, its channel costs at the picked ticks are the
trace's ``cost_<channel>`` columns (``lmm-studio trace``) and its transition marks are the trace's
transitioned ticks."""
from __future__ import annotations

import csv
import json

import pytest

from studio_testutil import run_reopened

pytestmark = pytest.mark.gui

SECONDS = 5
CHANGE_TICK = 100            # the session's hip_velocity weight goes 1 -> 3 before this tick is stepped


def test_the_channel_cost_timeline_of_a_reopened_session_is_the_trace(xvfb_display, studio_cache, tmp_path):
    from app.cli import main as cli_main

    session, trace = tmp_path / "s.lmmsession", tmp_path / "t.csv"
    events = tmp_path / "events.json"
    events.write_text(json.dumps({"events": [{"tick": CHANGE_TICK, "kind": "tuning", "payload": {
        "field": "feature_weights", "channel": "hip_velocity", "new": 3.0}}]}))
    assert cli_main(["run", "--controller", "mm", "--input", "builtin:random:1", "--seconds", str(SECONDS),
                     "--events", str(events), "--session", str(session), "--quiet"]) == 0
    assert cli_main(["trace", str(session), "--out", str(trace)]) == 0
    rows = {int(r["tick"]): r for r in csv.DictReader(trace.open()) if r["controller"] == "mm"}
    ticks = SECONDS * 60
    assert sorted(rows) == list(range(ticks))
    # history tick n (the studio's numbering) is the pose after n steps: the trace's tick n - 1
    picked = [1, CHANGE_TICK, CHANGE_TICK + 1, 217, ticks]
    # asked from frame 140 on: the timeline's job (a child process loading the database) has had seconds
    script = [{"frame": 3, "do": "search_view", "view": "channels"},
              {"frame": 8, "do": "window_size", "window": "search", "width": 505, "height": 560},
              *({"frame": 140 + 3 * i, "do": "scrub", "tick": t} for i, t in enumerate(picked)),
              *({"frame": 141 + 3 * i, "do": "capture", "label": f"t{t}"} for i, t in enumerate(picked)),
              {"frame": 160, "do": "screenshot", "path": str(tmp_path / "channel_costs.png")}]
    data = run_reopened(session, tmp_path, xvfb_display, studio_cache, script, frames=165)
    assert not data["errors"], data["errors"]
    transitioned = [t + 1 for t, r in rows.items() if r["transitioned"] == "1"]
    assert transitioned                                       # the marks have something to equal
    for t in picked:
        shown = data["labels"][f"t{t}"]
        costs = shown["panels"]["search"]["channel_costs"]
        assert shown["displayed_tick"] == t and costs["tick"] == t
        assert costs["source"] == "session" and costs["controller"] == "mm", costs["status"]
        assert (costs["first_tick"], costs["ticks"]) == (1, ticks)          # every tick of the session
        assert costs["row"] == [float(rows[t - 1][f"cost_{c}"]) for c in costs["channels"]], t
        assert costs["transitions"] == transitioned
        assert 0 < costs["drawn_points"] <= ticks
    assert (tmp_path / "channel_costs.png").stat().st_size > 0


def test_a_click_on_the_channel_costs_shows_that_tick_xdotool(xvfb_display, studio_cache, tmp_path):
    """A real click (xdotool) a quarter of the way into the channel costs plot of a reopened session shows
    the tick under the pointer: the tick the plot says it picked, within the plot's quarter."""
    import shutil
    import time

    from app.cli import main as cli_main
    from studio_testutil import RealKeyStudio

    if shutil.which("xdotool") is None:
        pytest.skip("xdotool is not installed")
    session = tmp_path / "s.lmmsession"
    assert cli_main(["run", "--controller", "mm", "--input", "builtin:random:1", "--seconds", str(SECONDS),
                     "--session", str(session), "--quiet"]) == 0
    rects = tmp_path / "rects.json"
    actions = [{"frame": 3, "do": "search_view", "view": "channels"},
               {"frame": 8, "do": "window_size", "window": "search", "width": 505, "height": 560},
               *({"frame": 9, "do": "show", "window": w, "show": False} for w in ("candidates", "latent", "stats")),
               {"frame": 100, "do": "write_rects", "path": str(rects), "items": ["chc_plot"]}]
    with RealKeyStudio(tmp_path, xvfb_display, studio_cache, actions, ["--open", str(session)]) as s:
        x0, y0, x1, y1 = s.rect(rects, "chc_plot")
        s.xdo("windowfocus", "--sync", s.win)
        s.xdo("mousemove", "--window", s.win, str(int(x0 + 0.25 * (x1 - x0))), str(int(y0 + 0.6 * (y1 - y0))))
        time.sleep(0.5)
        s.xdo("click", "1")
        time.sleep(1.5)
    assert s.returncode == 0, s.stderr[-3000:]
    final = s.dump()["final"]
    picked = final["search"]["channel_costs"]["picked"]
    ticks = SECONDS * 60
    assert picked is not None and 0.05 * ticks < picked < 0.45 * ticks, picked
    assert final["timeline"]["tick"] == picked
