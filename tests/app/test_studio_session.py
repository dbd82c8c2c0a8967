"""The studio's session file and undo, in one real studio run under Xvfb: a recording that starts
mid-session (sliders moved through their widgets before and during it, a reset inside it, five slider
moves undone and redone) replays headless to the studio's own BVH files byte for byte."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from studio_testutil import ROOT

pytestmark = pytest.mark.gui

MOVES = [("run_forward_speed_m_s", None, 1.75), ("walk_forward_speed_m_s", None, 1.0),
         ("top_k", None, 12), ("feature_weights", "hip_velocity", 0.25), ("tag_excluded", "crouch", True)]


@pytest.fixture(scope="module")
def studio_session(xvfb_display, studio_cache, lmm_weights, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("studio-session")
    script = [
        {"frame": 20, "do": "set_tuning", "field": "run_sideways_speed_m_s", "value": 1.25},
        {"frame": 40, "do": "record_start", "path": str(tmp / "take.bvh"), "which": ["mm", "lmm"]},
        {"frame": 60, "do": "set_tuning", "field": "tag_bias", "channel": "walk", "value": 0.5},
        {"frame": 80, "do": "reset_characters"},
        *({"frame": 100 + 4 * i, "do": "set_tuning", "field": f, "channel": c, "value": v}
          for i, (f, c, v) in enumerate(MOVES)),
        *({"frame": 125 + i, "do": "undo"} for i in range(5)),
        *({"frame": 135 + i, "do": "redo"} for i in range(5)),
        {"frame": 160, "do": "record_stop"},
    ]
    args = ["--frames", 170, "--input", "builtin:circle"]
    if lmm_weights:
        args += ["--weights", lmm_weights]
    (tmp / "script.json").write_text(json.dumps({"actions": script}))
    env = dict(os.environ, DISPLAY=xvfb_display, LMM_STUDIO_CONFIG=str(tmp / "config"),
               LMM_STUDIO_CACHE=str(studio_cache), PYTHONPATH=str(ROOT), LP_NUM_THREADS="0")
    proc = subprocess.run([sys.executable, "-m", "app.cli", *map(str, args), "--script", str(tmp / "script.json"),
                           "--dump-state", str(tmp / "dump.json"), "--no-gamepads"],
                          cwd=tmp, env=env, capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return {"dump": json.loads((tmp / "dump.json").read_text()), "dir": tmp, "lmm": bool(lmm_weights)}


def test_the_studios_recording_replays_byte_for_byte(studio_session):
    from lmm.session.reader import open_session

    d, tmp = studio_session["dump"], studio_session["dir"]
    rec = d["recordings"][0]
    session = tmp / "take.lmmsession"
    assert rec["frames"] == 120 and rec["message"].endswith("; session take.lmmsession"), rec
    f = open_session(session)
    # the session starts at the studio's start (the characters were never reset before the recording),
    # holds the slider moved before it, and the recording's first tick
    assert f.recording_from == 40 and f.ticks == 160 and f.meta["closed"]
    kinds = [(e.kind, e.payload.get("field") or e.payload.get("id")) for e in f.events]
    assert kinds[0] == ("tuning", "run_sideways_speed_m_s") and ("reset", None) in kinds
    assert sum(k == "tuning" for k, _ in kinds) == 2 + 15          # 2 moves, 5 moves, 5 undone, 5 redone
    f.close()
    names = ["mm", "lmm"] if studio_session["lmm"] else ["mm"]
    for name in names:
        again = tmp / f"again_{name}.bvh"
        proc = subprocess.run([sys.executable, "-m", "app.cli", "replay", str(session), "--record", str(again),
                               "--controller", name], cwd=tmp, capture_output=True, text=True, timeout=240,
                              env=dict(os.environ, PYTHONPATH=str(ROOT)))
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert "fingerprints match" in proc.stdout
        assert again.read_bytes() == Path(rec["written"][name]).read_bytes(), name


def test_five_slider_moves_undone_and_redone_exactly(studio_session):
    d = studio_session["dump"]
    by_frame = {t["frame_submitted"]: t["tuning_seen"] for t in d["ticks"] if t.get("tuning_seen")}

    def typed(v):
        return {k: (type(x).__name__, x) for k, x in v.items()} if isinstance(v, dict) else (type(v).__name__, v)

    def same(a, b):
        return a.keys() == b.keys() and all(typed(a[k]) == typed(b[k]) for k in a)

    before, moved, undone, redone = by_frame[99], by_frame[117], by_frame[130], by_frame[140]
    for field, channel, value in MOVES:
        got = moved[field] if channel is None else moved[field][channel]
        assert got == value and got != (before[field] if channel is None else before[field][channel]), field
    assert same(undone, before) and same(redone, moved)
    assert not same(before, moved)


def test_the_session_reopens_with_every_tick_on_the_timeline(studio_session, xvfb_display, studio_cache):
    """lmm-studio --open take.lmmsession: the timeline covers all 160 ticks, and a tick picked before and one
    after the reset show the characters where the first run had them (its roots, every controller)."""
    d, tmp = studio_session["dump"], studio_session["dir"]
    script = [{"frame": 5, "do": "scrub", "tick": 60}, {"frame": 8, "do": "capture", "label": "early"},
              {"frame": 10, "do": "scrub", "tick": 131}, {"frame": 13, "do": "capture", "label": "late"}]
    (tmp / "open.json").write_text(json.dumps({"actions": script}))
    env = dict(os.environ, DISPLAY=xvfb_display, LMM_STUDIO_CONFIG=str(tmp / "config2"),
               LMM_STUDIO_CACHE=str(studio_cache), PYTHONPATH=str(ROOT), LP_NUM_THREADS="0")
    proc = subprocess.run([sys.executable, "-m", "app.cli", "--open", str(tmp / "take.lmmsession"), "--frames", "16",
                           "--script", str(tmp / "open.json"), "--dump-state", str(tmp / "open_dump.json"),
                           "--no-gamepads"], cwd=tmp, env=env, capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr[-3000:]
    opened = json.loads((tmp / "open_dump.json").read_text())
    assert opened["tick_count"] == 0 and not opened["errors"], opened["errors"]      # nothing simulated live
    first = {t["frame_submitted"]: t["roots"] for t in d["ticks"]}     # one tick a frame: step i at frame i
    for label, tick in (("early", 60), ("late", 131)):
        got = opened["labels"][label]
        assert got["displayed_tick"] == tick
        assert got["snapshot_roots"] == first[tick - 1], label
        timeline = got["panels"]["timeline"]
        assert (timeline["oldest"], timeline["newest"], timeline["tick"]) == (1, 160, tick), timeline
    assert "SESSION   |   tick 131" in opened["labels"]["late"]["panels"]["menu"]["status"]
