"""The Motion Search panel in the real studio under Xvfb: a scripted run searches with the timeline window
(live and at a picked tick) and with a BVH file range; bad input is one line in the error dialog and the
studio runs on."""
from __future__ import annotations

import math

import pytest

from lmm import DEFAULT_MANIFEST
from lmm.data import bvh
from lmm.data.manifest import load_manifest

pytestmark = pytest.mark.gui


def test_motion_search_panel_searches_and_reports_bad_input(run_studio, tmp_path):
    clips = load_manifest(DEFAULT_MANIFEST).clips
    take = clips[0].file
    robot = bvh.load(take).slice(0, 100)
    robot.names = [n.replace("Hand", "Paw") for n in robot.names]
    bvh.save(tmp_path / "robot.bvh", robot)
    (tmp_path / "empty").mkdir()
    labels = {c.source for c in clips}
    search = {"frame": 0, "do": "motion_search", "in": str(DEFAULT_MANIFEST), "top": 5}
    script = [
        {**search, "frame": 100, "source": "timeline", "seconds": 1.0},
        {"frame": 101, "do": "capture", "label": "live"},
        {"frame": 104, "do": "pause"},
        {"frame": 106, "do": "scrub", "back": 40},
        {**search, "frame": 110, "source": "timeline", "seconds": 1.0},
        {"frame": 111, "do": "capture", "label": "scrubbed"},
        {**search, "frame": 114, "source": "file", "file": str(take), "frames": "300:99999"},
        {**search, "frame": 116, "source": "file", "file": str(tmp_path / "robot.bvh"), "frames": "0:50"},
        {**search, "frame": 118, "source": "file", "file": str(take), "frames": "0:60", "in": str(tmp_path / "empty")},
        {**search, "frame": 120, "source": "file", "file": str(take), "frames": "120:120"},
        {**search, "frame": 124, "source": "file", "file": str(take), "frames": "200:260"},
        {"frame": 125, "do": "capture", "label": "file"},
        {"frame": 128, "do": "screenshot", "path": str(tmp_path / "motion_search.png")},
    ]
    r = run_studio("--frames", 135, "--no-lmm", "--input", "builtin:circle", script=script, timeout=240)
    assert r.rc == 0, r.stderr[-3000:]
    d = r.dump
    assert d["frames_run"] == 135                     # it ran on through every error

    live = d["labels"]["live"]["panels"]["motion_search"]
    assert len(live["results"]) == 5 and live["query_frames"] == 30
    for m in live["results"]:
        assert m["file"] in labels and 0 <= m["start_frame"] < m["end_frame"] and math.isfinite(m["distance"])
    scrubbed = d["labels"]["scrubbed"]
    state = scrubbed["panels"]["motion_search"]
    assert state["query_end_tick"] == scrubbed["displayed_tick"] < live["query_end_tick"] + 10
    assert state["results"] != live["results"]

    found = d["labels"]["file"]["panels"]["motion_search"]
    assert found["results"][0] == {"file": clips[0].source, "start_frame": 200, "end_frame": 260, "distance": 0.0}
    assert found["query_end_tick"] is None and found["selected"] == 0

    messages = [e["message"] for e in d["errors"]]
    assert any("go past the end" in m and take.name in m for m in messages), messages
    assert any("robot.bvh: cannot match the key joints left_hand, right_hand" in m for m in messages), messages
    assert any("the folder holds no .bvh files" in m for m in messages), messages
    assert any("120:120 are an empty range" in m for m in messages), messages
    assert all("\n" not in m for m in messages)
    assert (tmp_path / "motion_search.png").stat().st_size > 10000
