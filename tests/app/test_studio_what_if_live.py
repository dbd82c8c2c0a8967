"""What if in the paused live studio, in one studio run under Xvfb (replayed input, every tick searching,
recorded with its session): pausing and setting a scratch feature weight re-ranks the shown tick's
candidates as a fresh search with that tuning at that tick does (the recorded session branched there), and
the channel costs tab shows the rewind history's costs by channel as the session's trace has them."""
from __future__ import annotations

import csv

import numpy as np
import pytest

from studio_testutil import run_scripted

pytestmark = pytest.mark.gui

PAUSE_FRAME = 70


def test_what_if_re_ranks_the_paused_live_tick_as_a_fresh_search(xvfb_display, studio_cache, tmp_path):
    from app.cli import main as cli_main
    from app.commands.session_common import open_with_database
    from lmm.session.seek import SessionSeeker

    take = tmp_path / "take.bvh"
    script = [{"frame": 2, "do": "set_tuning", "field": "search_interval_s", "value": 0.0},
              {"frame": 4, "do": "record_start", "path": str(take), "which": ["mm"]},
              {"frame": PAUSE_FRAME, "do": "pause"}, {"frame": PAUSE_FRAME + 2, "do": "capture", "label": "paused"},
              {"frame": PAUSE_FRAME + 3, "do": "what_if", "field": "feature_weights", "channel": "hip_velocity",
               "value": 4.0},
              {"frame": PAUSE_FRAME + 5, "do": "capture", "label": "what_if"},
              {"frame": PAUSE_FRAME + 6, "do": "search_view", "view": "channels"},
              {"frame": PAUSE_FRAME + 9, "do": "capture", "label": "channels"},
              {"frame": PAUSE_FRAME + 10, "do": "screenshot", "path": str(tmp_path / "live_what_if.png")},
              {"frame": PAUSE_FRAME + 12, "do": "resume"},
              {"frame": PAUSE_FRAME + 40, "do": "record_stop"}]
    # the run checks what the tick worker prepared against the GUI thread's own, as run_studio's runs do
    dump = run_scripted(["--no-lmm", "--input", "builtin:random:1", "--frames", PAUSE_FRAME + 45], tmp_path,
                        xvfb_display, studio_cache, script, env_extra={"LMM_STUDIO_CHECK_PREPARED": "1"})
    assert not dump["errors"], dump["errors"]
    prepared = dump["prepared"]
    assert prepared["checked"] and prepared["used"]["search"] > 0
    assert not prepared["mismatches"], prepared
    labels = dump["labels"]
    tick = labels["what_if"]["displayed_tick"]
    assert labels["paused"]["displayed_tick"] == tick > 30
    shown = labels["what_if"]["panels"]["candidates"]
    assert shown["what_if"]["tick"] == tick
    assert "WHAT IF (scratch tuning: feature_weights.hip_velocity=4.0)" in shown["status"]
    rerank = [r["frame"] for r in shown["rows"]]
    assert rerank != [r["frame"] for r in labels["paused"]["panels"]["candidates"]["rows"]]
    # the fresh search: the recorded session branched with the scratch weight at the step that made the tick
    path = take.with_suffix(".lmmsession")
    session, db, features, _ = open_with_database(path)
    fresh = SessionSeeker(session, db, features, branch={"feature_weights": {"hip_velocity": 4.0}},
                          from_tick=tick - 1).seek(tick - 1)[1]["mm"]
    assert fresh.searched and fresh.candidates.frames.tolist() == rerank
    assert np.allclose(fresh.candidates.costs, [r["total"] for r in shown["rows"]], rtol=1e-5, atol=1e-6)
    session.close()
    # the channel costs tab, live: the rewind history (ticks 1 .. the shown one) as the trace has it
    trace = tmp_path / "t.csv"
    assert cli_main(["trace", str(path), "--out", str(trace)]) == 0
    rows = {int(r["tick"]): r for r in csv.DictReader(trace.open())}
    costs = labels["channels"]["panels"]["search"]["channel_costs"]
    assert costs["source"] == "history" and (costs["first_tick"], costs["ticks"], costs["tick"]) == (1, tick, tick)
    assert np.allclose(costs["row"], [float(rows[tick - 1][f"cost_{c}"]) for c in costs["channels"]], rtol=1e-6)
    assert costs["transitions"] == [t + 1 for t, r in sorted(rows.items()) if r["transitioned"] == "1" and t < tick]
