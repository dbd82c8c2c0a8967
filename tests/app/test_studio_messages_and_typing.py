"""The real studio under Xvfb, for what new users ran into: typing into a field paused the simulation,
an empty recording, the help dialog titled "Error", "MM step 0.00 ms", overlapping character labels,
and a restored layout that hid panels without saying so."""
from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import pytest

from studio_testutil import RealKeyStudio

pytestmark = pytest.mark.gui


def _overlap(a, b) -> bool:
    ax, ay, aw, ah = a
    bx, by, bw, bh = b
    return ax < bx + bw and bx < ax + aw and ay < by + bh and by < ay + ah


def test_recording_help_stats_and_labels(run_studio, tmp_path, lmm_weights):
    take = tmp_path / "takes" / "take.bvh"
    script = [{"frame": 5, "do": "record_start", "path": str(take), "which": ["mm"]},
              {"frame": 5, "do": "record_stop"},                     # Record, Stop: nothing recorded
              {"frame": 7, "do": "capture", "label": "empty"},
              {"frame": 10, "do": "record_start", "path": str(take), "which": ["mm"]},
              {"frame": 20, "do": "record_stop"},
              {"frame": 25, "do": "record_start", "path": str(take), "which": ["mm"]},
              {"frame": 35, "do": "record_stop"},
              {"frame": 37, "do": "capture", "label": "second"},
              {"frame": 40, "do": "help"},
              {"frame": 42, "do": "capture", "label": "help"},
              {"frame": 45, "do": "pause"}]                           # most frames finish no tick now
    args = ["--frames", 90, "--input", "builtin:circle"] + (["--weights", lmm_weights] if lmm_weights else [])
    r = run_studio(*args, script=script)
    assert r.rc == 0, r.stderr[-3000:]
    d = r.dump
    empty, first, second = d["recordings"]
    # b: nothing recorded -> said so, no file; a second take never overwrites the first
    assert empty["frames"] == 0 and empty["written"] == {}
    assert Path(first["written"]["mm"]).name == "take.bvh"         # the empty take left no file behind
    assert "nothing" in d["labels"]["empty"]["panels"]["recording"]["status"]
    assert first["frames"] == 10 and second["frames"] == 10
    assert first["written"]["mm"] != second["written"]["mm"]
    assert all(first["exists"].values()) and all(second["exists"].values())
    assert Path(second["written"]["mm"]).name in d["labels"]["second"]["panels"]["recording"]["status"]
    # c: Help > Keys and mouse is information, titled so, not an error
    assert d["labels"]["help"]["panels"]["dialog"] == {"title": "Keys and mouse", "shown": True}
    assert d["errors"] == []
    # f: controller time is per tick, not pulled to zero by the frames that finished no tick
    parts = d["frame_times"]["parts_ms"]
    for name in d["controllers"]:
        assert parts[name] is not None and parts[name] > 0.05, parts
    # g: the character labels (and the ragdoll's) do not overlap; the check used to run only for exactly two
    # labels, so it stopped checking once the ragdoll got its own
    labels = d["final"]["viewport"].get("labels", {})
    assert {"mm", "lmm"} <= set(labels) and d["controllers"] == ["mm", "lmm"], labels
    names = sorted(labels)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            assert not _overlap(labels[a], labels[b]), (a, b, labels)


def test_restored_layout_says_which_panels_are_hidden(run_studio, tmp_path):
    config = tmp_path / "cfg"
    r = run_studio("--frames", 4, "--no-lmm", "--layout", "compare", config=config)   # hides two panels
    assert r.rc == 0, r.stderr[-3000:]
    r2 = run_studio("--frames", 14, "--no-lmm", script=[{"frame": 12, "do": "capture", "label": "start"}],
                    config=config)
    assert r2.rc == 0, r2.stderr[-3000:]
    assert r2.dump["layout"] == "user"
    status = r2.dump["labels"]["start"]["panels"]["menu"]["status"]
    assert "layout: user" in status and "Tuning" in status and "Recording & Input" in status
    assert "Windows menu" in status


def test_typing_into_fields_never_pauses_or_moves_xdotool(xvfb_display, studio_cache, tmp_path):
    """Ctrl+click a slider and type 6.0 (the '.' is the step key), then type into the record path
    (W, A, S, D and Space are movement and pause keys): the simulation stays live and still."""
    if shutil.which("xdotool") is None:
        pytest.skip("xdotool is not installed")
    rects = tmp_path / "rects.json"
    slider = "tun_run_forward_speed_m_s"
    actions = [{"frame": 20, "do": "write_rects", "path": str(rects), "items": [slider, "rec_path"]}]

    def centre(item, across=0.5):
        x0, y0, x1, y1 = json.loads(rects.read_text())[item]
        return str(int(x0 + (x1 - x0) * across)), str(int((y0 + y1) / 2))

    with RealKeyStudio(tmp_path, xvfb_display, studio_cache, actions, ["--layout", "default"]) as s:
        xdo, win = s.xdo, s.win
        for _ in range(120):
            if rects.exists():
                break
            time.sleep(0.5)
        time.sleep(1.0)
        xdo("windowfocus", "--sync", win)
        xdo("mousemove", "--window", win, *centre(slider, 0.25))   # on the slider, not its label
        xdo("keydown", "ctrl")
        xdo("click", "1")
        xdo("keyup", "ctrl")
        time.sleep(0.5)
        xdo("type", "--delay", "120", "2.5")
        xdo("key", "Return")
        time.sleep(0.5)
        xdo("mousemove", "--window", win, *centre("rec_path"))
        xdo("click", "1")
        time.sleep(0.3)
        xdo("key", "ctrl+a")
        xdo("type", "--delay", "120", "w s.a d,x f")
        xdo("key", "space")
        time.sleep(1.0)
        xdo("key", "Escape")
    assert s.returncode == 0, s.stderr[-3000:]
    d = s.dump()
    assert all(f["live"] and not f["paused"] for f in d["frames"]), "typing paused or stepped the simulation"
    assert not any(t["input"]["left_y"] or t["input"]["left_x"] for t in d["ticks"]), "typing moved the character"
    assert d["final"]["viewport"]["camera"] is not None
    speeds = {t["tuning_seen"]["run_forward_speed_m_s"] for t in d["ticks"] if t["tuning_seen"]}
    assert 2.5 in speeds, "the typed value did not reach the tuning"
