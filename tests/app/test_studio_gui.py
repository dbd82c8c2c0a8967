"""The real studio under Xvfb, in a subprocess, driven by a script of timed actions (and once by real
key presses through xdotool); assertions read the JSON state it dumps at exit."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest

from app import layout_files as layouts

from studio_testutil import CORPUS, ROOT, RealKeyStudio

pytestmark = pytest.mark.gui

RUN_SPEEDS = ("run_forward_speed_m_s", "run_sideways_speed_m_s", "run_backwards_speed_m_s")


def first_frame_with_tick(dump, tick):
    return next(f for f in dump["frames"] if f["newest_tick"] == tick)


# -----------------------------------------------------------------------------------------------
# one scripted run: input, sliders, recording, panels
# -----------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def circle_run(xvfb_display, studio_cache, lmm_weights, tmp_path_factory):
    """150 frames of builtin:circle with both characters (when weights exist); at frame 60 every run
    speed goes to 1.0 m/s, a feature weight to 0 and a tag bias to 0.5 through the sliders, and a tag's
    exclusion checkbox is ticked; frames 20-120 are recorded."""
    tmp = tmp_path_factory.mktemp("circle")
    script = [
        {"frame": 20, "do": "record_start", "path": str(tmp / "take.bvh"), "which": ["mm", "lmm"]},
        *({"frame": 60, "do": "set_tuning", "field": f, "value": 1.0} for f in RUN_SPEEDS),
        {"frame": 60, "do": "set_tuning", "field": "feature_weights", "channel": "hip_velocity", "value": 0.0},
        {"frame": 60, "do": "set_tuning", "field": "tag_bias", "channel": "walk", "value": 0.5},
        {"frame": 60, "do": "set_tuning", "field": "tag_excluded", "channel": "crouch", "value": True},
        {"frame": 90, "do": "inspect", "controller": "lmm"},
        {"frame": 120, "do": "record_stop"},
        {"frame": 149, "do": "capture", "label": "end"},
    ]
    args = ["--frames", 150, "--input", "builtin:circle", "--screenshot", tmp / "circle.png"]
    if lmm_weights:
        args += ["--weights", lmm_weights]
    (tmp / "script.json").write_text(json.dumps({"actions": script}))
    dump_path = tmp / "dump.json"
    env = dict(os.environ, DISPLAY=xvfb_display, LMM_STUDIO_CONFIG=str(tmp / "config"),
               LMM_STUDIO_CACHE=str(studio_cache), PYTHONPATH=str(ROOT), LP_NUM_THREADS="0",
               LMM_STUDIO_CHECK_PREPARED="1")
    proc = subprocess.run([sys.executable, "-m", "app.cli", *map(str, args), "--script", str(tmp / "script.json"),
                           "--dump-state", str(dump_path), "--no-gamepads"],
                          cwd=tmp, env=env, capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return {"dump": json.loads(dump_path.read_text()), "dir": tmp, "lmm": bool(lmm_weights), "stderr": proc.stderr}


def test_scripted_input_moves_both_characters(circle_run):
    d = circle_run["dump"]
    assert d["frames_run"] == 150 and d["tick_count"] == 150
    expected = ["mm", "lmm"] if circle_run["lmm"] else ["mm"]
    assert d["controllers"] == expected, d.get("lmm_problem")
    assert d["shared_tuning"] is True
    first, last = d["ticks"][0]["roots"], d["ticks"][-1]["roots"]
    for name in expected:
        moved = np.linalg.norm(np.subtract(last[name], first[name]))
        assert moved > 1.5, (name, moved)
    # the replayed input is what the controllers got
    ticks = {t["tick"]: t for t in d["ticks"]}
    assert sorted(ticks) == list(range(1, 151))
    assert ticks[30]["input"]["left_y"] != 0.0 or ticks[30]["input"]["left_x"] != 0.0


def test_screenshot_of_the_whole_window(circle_run):
    from PIL import Image

    img = Image.open(circle_run["dir"] / "circle.png")
    assert img.size == (1600, 900)
    a = np.asarray(img.convert("RGB"), dtype=np.float32)
    assert a.std() > 10.0                      # not a blank frame


def test_slider_change_reaches_the_runtime_on_the_next_frame(circle_run):
    d = circle_run["dump"]
    ticks = {t["tick"]: t for t in d["ticks"]}
    # the sliders moved at the start of frame 60; frame 60 hands tick 61 to the controllers, which
    # frame 61 shows: the very next frame
    changed = min(t for t, rec in ticks.items() if rec["tuning_seen"]["run_forward_speed_m_s"] == 1.0)
    assert changed == 61 and ticks[changed]["frame_submitted"] == 60
    assert d["frames"][61]["displayed_tick"] == 61
    before, after = ticks[changed - 1], ticks[changed]
    for f in RUN_SPEEDS:
        assert after["tuning_seen"][f] == 1.0
    assert before["tuning_seen"]["run_forward_speed_m_s"] == 3.5
    assert before["tuning_seen"]["feature_weights"]["hip_velocity"] == 1.0
    assert after["tuning_seen"]["feature_weights"]["hip_velocity"] == 0.0
    # the per-tag widgets: a bias slider and an exclusion checkbox, with no error dialog
    assert (before["tuning_seen"]["tag_bias"]["walk"], after["tuning_seen"]["tag_bias"]["walk"]) == (0.0, 0.5)
    assert (before["tuning_seen"]["tag_excluded"]["crouch"], after["tuning_seen"]["tag_excluded"]["crouch"]) == \
        (False, True)
    assert not [e for e in d["errors"] if e["title"] == "Tuning"], d["errors"]
    # the effect, not just the value: the desired velocity is capped by the new speeds at once
    for name, speed in after["desired_speed"].items():
        assert speed <= 1.0 + 1e-6, name
        assert before["desired_speed"][name] > 1.2, name


def test_recording_writes_bvh_our_reader_loads(circle_run):
    from lmm.data import bvh
    from lmm.data.inputs import load_input_csv

    d = circle_run["dump"]
    rec = d["recordings"][0]
    assert rec["started"] == 20 and rec["stopped"] == 120
    names = ["mm", "lmm"] if circle_run["lmm"] else ["mm"]
    for name in names:
        anim = bvh.load(rec["written"][name])
        assert anim.n_frames == 100
        pos = anim.global_positions()
        assert np.isfinite(pos).all() and np.ptp(pos[:, 0, [0, 2]], axis=0).max() > 50.0   # cm, it moved
    log = load_input_csv(rec["written"]["input"])
    assert log.n_rows > 10 and log.duration == pytest.approx(100 / 60, abs=0.05)


def test_panels_show_the_live_tick(circle_run):
    d = circle_run["dump"]
    end = d["labels"]["end"]
    p = end["panels"]
    tick = end["displayed_tick"]
    assert tick == d["frames"][149]["displayed_tick"] == 149
    assert p["timeline"]["tick"] == tick and p["viewport"]["tick"] == tick
    assert p["features"]["query"] is not None and len(p["features"]["query"]) == 27
    assert p["candidates"]["rows"] and p["candidates"]["rows"][0]["channels"]
    assert p["stats"]["fps"] > 0
    assert p["windows"]["viewport"]["shown"]
    # the shipped weights are in the repository: LMM runs (were it off, this test would check MM only)
    assert circle_run["lmm"], "no LMM weights for the studio"
    assert p["features"]["projected"] is not None
    assert p["latent"]["lmm_latest"] is not None and len(p["latent"]["lmm_latest"]) == 32
    assert p["search"]["nn_frame"] >= 0 and p["search"]["searches"] > 0
    assert p["search"]["projected_frame"] >= 0 and p["search"]["distance"] is not None
    # inspecting LMM: the query bars are LMM's
    assert np.allclose(p["features"]["query"], end["snapshot_query"]["lmm"], atol=1e-5)


def test_the_tick_worker_prepares_what_the_panels_show(circle_run):
    """The numeric share of the 3D view, the plot panels and the candidates table (motion matching's
    ranked search included) is worked out on the tick worker for the next frame; with
    LMM_STUDIO_CHECK_PREPARED every used result was compared with the GUI thread's own and none differed
    (slider changes, a change of the inspected controller and recording on the way)."""
    prep = circle_run["dump"]["prepared"]
    assert prep["checked"] and prep["mismatches"] == []
    for key in ("viewport", "features", "latent", "search", "timeline", "candidates"):
        assert prep["used"].get(key, 0) >= 120, prep        # of 150 frames: nearly all of them
        assert prep["inline"].get(key, 0) >= 1, prep        # the first frame has nothing prepared


# -----------------------------------------------------------------------------------------------
# layouts
# -----------------------------------------------------------------------------------------------

def _rects(windows):
    return {k: tuple(v["pos"]) + tuple(v["size"]) for k, v in windows.items() if v["shown"]}


def _expected(name):
    return {k: tuple(v) for k, v in layouts.BUILTIN[name].items() if v is not None}


def test_ui_antialiasing_is_off_on_software_gl_unless_asked(circle_run, run_studio):
    """--ui-antialiasing auto (the default) turns dearpygui's anti-aliased lines and fills off where the GL
    renderer rasterises on the CPU (their fringes cost about a tenth of the frame rate there) and leaves
    them on elsewhere; on and off are obeyed whatever the renderer."""
    from viewer.renderer import SOFTWARE_RENDERERS

    d = circle_run["dump"]
    software = any(s in d["final"]["viewport"]["gl_renderer"].lower() for s in SOFTWARE_RENDERERS)
    assert set(d["ui_antialiasing"]) == {"anti_aliased_lines", "anti_aliased_lines_use_tex", "anti_aliased_fill"}
    assert all(v is (not software) for v in d["ui_antialiasing"].values()), (d["final"]["viewport"]["gl_renderer"],
                                                                             d["ui_antialiasing"])
    for choice, on in (("on", True), ("off", False)):
        r = run_studio("--frames", 3, "--no-lmm", "--ui-antialiasing", choice)
        assert r.rc == 0, r.stderr[-3000:]
        assert all(v is on for v in r.dump["ui_antialiasing"].values()), (choice, r.dump["ui_antialiasing"])
    r = run_studio("--frames", 3, "--ui-antialiasing", "sometimes")
    assert r.rc == 2 and "--ui-antialiasing" in r.stderr and r.stderr.count("\n") == 1 and r.dump is None


def test_layouts_switch_and_the_users_layout_is_restored(run_studio, tmp_path):
    config = tmp_path / "cfg"
    script = [{"frame": 3, "do": "capture", "label": "start"},
              {"frame": 4, "do": "layout", "name": "compare"},
              {"frame": 8, "do": "capture", "label": "compare"},
              {"frame": 9, "do": "layout", "name": "default"},
              {"frame": 13, "do": "capture", "label": "default"},
              {"frame": 14, "do": "layout", "name": str(ROOT / "layouts" / "compare.ini")},
              # File > Save layout as..., switch away, Layout > Load layout file...
              {"frame": 18, "do": "open", "kind": "layout_save", "path": str(tmp_path / "mine.ini")},
              {"frame": 19, "do": "layout", "name": "tuning"},
              {"frame": 22, "do": "open", "kind": "layout_load", "path": str(tmp_path / "mine.ini")},
              {"frame": 26, "do": "capture", "label": "mine"}]
    r = run_studio("--frames", 28, "--layout", "tuning", "--no-lmm", script=script, config=config)
    assert r.rc == 0, r.stderr[-3000:]
    d = r.dump
    assert d["errors"] == []
    for label, name in (("start", "tuning"), ("compare", "compare"), ("default", "default")):
        got = _rects(d["labels"][label]["panels"]["windows"])
        assert got == _expected(name), label
    assert _rects(d["labels"]["mine"]["panels"]["windows"]) == _expected("compare")
    assert d["layout"] == "mine"
    saved = config / "layout.ini"
    assert saved.is_file() and "[LmmStudio][Layout]" in saved.read_text()
    # next start, no --layout: the user's last layout (compare) comes back
    r2 = run_studio("--frames", 4, "--no-lmm", script=[{"frame": 2, "do": "capture", "label": "start"}],
                    config=config)
    assert r2.rc == 0, r2.stderr[-3000:]
    assert r2.dump["layout"] == "user"
    assert _rects(r2.dump["labels"]["start"]["panels"]["windows"]) == _expected("compare")


# -----------------------------------------------------------------------------------------------
# rewind
# -----------------------------------------------------------------------------------------------

def test_rewind_scrub_shows_an_older_tick_everywhere(run_studio, tmp_path, lmm_weights):
    from PIL import Image

    script = [{"frame": 100, "do": "screenshot", "path": str(tmp_path / "live.png")},
              {"frame": 101, "do": "pause"},
              {"frame": 101, "do": "scrub", "back": 80},
              {"frame": 104, "do": "screenshot", "path": str(tmp_path / "scrubbed.png")},
              {"frame": 105, "do": "capture", "label": "scrubbed"},
              {"frame": 106, "do": "step", "n": -1},
              {"frame": 108, "do": "capture", "label": "stepped"},
              {"frame": 110, "do": "live"}]
    args = ["--frames", 130, "--input", "builtin:circle"] + (["--weights", lmm_weights] if lmm_weights else [])
    r = run_studio(*args, script=script)
    assert r.rc == 0, r.stderr[-3000:]
    d = r.dump
    frames = d["frames"]
    newest = frames[101]["newest_tick"]
    assert all(f["newest_tick"] == newest for f in frames[101:110])      # paused: nothing simulated
    assert frames[-1]["newest_tick"] > newest                           # live again afterwards
    cap = d["labels"]["scrubbed"]
    tick = cap["displayed_tick"]
    assert tick == newest - 80
    # the 3D view and the panels show that older tick, exactly as it was live
    live_then = first_frame_with_tick(d, tick)
    for name, root in cap["panels"]["viewport"]["roots"].items():
        assert np.allclose(root, live_then["roots"][name], atol=1e-5)
        assert not np.allclose(root, frames[101]["roots"][name], atol=1e-2)
    p = cap["panels"]
    assert p["viewport"]["tick"] == tick and p["timeline"]["tick"] == tick and p["search"]["tick"] == tick
    assert p["latent"]["end_tick"] == tick and p["timeline"]["live"] is False
    assert np.allclose(p["features"]["query"], cap["snapshot_query"]["mm"], atol=1e-5)
    assert d["labels"]["stepped"]["displayed_tick"] == tick - 1
    # and the pixels of the 3D view differ from the live image
    live = np.asarray(Image.open(tmp_path / "live.png").convert("RGB"), np.float32)
    old = np.asarray(Image.open(tmp_path / "scrubbed.png").convert("RGB"), np.float32)
    rect = layouts.BUILTIN["default"]["viewport"]
    x, y, w, h = rect
    region = (slice(y + 80, y + h - 10), slice(x + 10, x + w - 10))
    assert np.abs(live[region] - old[region]).mean() > 2.0


# -----------------------------------------------------------------------------------------------
# broken files
# -----------------------------------------------------------------------------------------------

def test_broken_files_show_an_error_and_the_studio_runs_on(run_studio, tmp_path):
    bad_preset = tmp_path / "bad_preset.json"
    bad_preset.write_text('{"run_forward_speed_m_s": "fast"')
    range_preset = tmp_path / "range_preset.json"
    range_preset.write_text('{"inertialization_halflife_s": 99}')
    good_preset = tmp_path / "good_preset.json"
    good_preset.write_text('{"run_forward_speed_m_s": 2.0}')
    bad_layout = tmp_path / "bad_layout.ini"
    bad_layout.write_text("not a layout\n")
    bad_weights = tmp_path / "bad_weights.npz"
    bad_weights.write_bytes(b"PK\x03\x04 truncated zip")
    bad_input = tmp_path / "bad_input.csv"
    bad_input.write_text("time,left_x\n0,abc\n")
    script = [{"frame": 5, "do": "open", "kind": "reference", "path": str(CORPUS / "truncated_frame.bvh")},
              {"frame": 7, "do": "open", "kind": "preset_load", "path": str(bad_preset)},
              {"frame": 9, "do": "open", "kind": "preset_load", "path": str(range_preset)},
              {"frame": 11, "do": "open", "kind": "layout_load", "path": str(bad_layout)},
              {"frame": 13, "do": "open", "kind": "weights", "path": str(bad_weights)},
              {"frame": 15, "do": "open", "kind": "input", "path": str(bad_input)},
              {"frame": 20, "do": "open", "kind": "preset_load", "path": str(good_preset)}]
    start_layout = tmp_path / "start_layout.ini"
    start_layout.write_bytes(b"\x00\x01 not a layout")
    r = run_studio("--frames", 30, "--no-lmm", "--input", "builtin:zigzag", "--layout", start_layout, script=script)
    assert r.rc == 0, r.stderr[-3000:]
    d = r.dump
    msgs = [e["message"] for e in d["errors"]]
    for f in ("start_layout.ini", "truncated_frame.bvh", "bad_preset.json", "range_preset.json", "bad_layout.ini",
              "bad_weights.npz", "bad_input.csv"):
        assert any(f in m for m in msgs), (f, msgs)
    assert len(msgs) == 7
    assert d["frames_run"] == 30 and d["tick_count"] == 30       # it kept simulating through the errors
    ticks = {t["tick"]: t for t in d["ticks"]}
    assert ticks[20]["tuning_seen"]["run_forward_speed_m_s"] == 3.5
    assert ticks[21]["tuning_seen"]["run_forward_speed_m_s"] == 2.0      # a good file still loads
    assert d["layout"] == "default"


def test_hostile_presets_and_layouts_never_take_the_studio_down(run_studio, tmp_path):
    """A preset nested 100,000 deep opened from the dialog is one error line; a saved user layout with
    Pos=inf is set aside for the default (and the next start is clean); layouts with Viewport=0,0 or a
    huge Size start the studio with the default layout."""
    deep = tmp_path / "deep_preset.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    good_preset = tmp_path / "good_preset.json"
    good_preset.write_text('{"run_forward_speed_m_s": 2.0}')
    config = tmp_path / "config"
    config.mkdir()
    (config / "layout.ini").write_text("[Window][###10001]\nPos=inf,0\nSize=300,200\n")
    script = [{"frame": 5, "do": "open", "kind": "preset_load", "path": str(deep)},
              {"frame": 8, "do": "open", "kind": "preset_load", "path": str(good_preset)}]
    r = run_studio("--frames", 14, "--no-lmm", "--input", "builtin:zigzag", script=script, config=config)
    assert r.rc == 0 and "Traceback" not in r.stderr, r.stderr[-3000:]
    msgs = [e["message"] for e in r.dump["errors"]]
    assert len(msgs) == 2, msgs
    assert any("deep_preset.json" in m and "\n" not in m for m in msgs), msgs
    assert any("layout.ini" in m and "default" in m for m in msgs), msgs
    assert (config / "layout.ini.bad").exists() and r.dump["layout"] == "default"
    ticks = {t["tick"]: t for t in r.dump["ticks"]}
    assert ticks[10]["tuning_seen"]["run_forward_speed_m_s"] == 2.0      # it went on, and loads good files
    for name, text in {"zero_viewport.ini": "[LmmStudio][Layout]\nViewport=0,0\n",
                       "huge_size.ini": "[Window][###10001]\nPos=0,0\nSize=100000000,100000000\n"}.items():
        bad = tmp_path / name
        bad.write_text("[Window][###10002]\nPos=0,22\nSize=300,200\n" + text)
        r = run_studio("--frames", 6, "--no-lmm", "--layout", bad, config=config)
        assert r.rc == 0 and "Traceback" not in r.stderr, r.stderr[-3000:]
        msgs = [e["message"] for e in r.dump["errors"]]
        assert len(msgs) == 1 and name in msgs[0] and "out of range" in msgs[0], msgs
        assert r.dump["layout"] == "default"
    # a screenshot target that cannot be written: one error line, exit 1, no file
    (tmp_path / "plain").write_text("not a folder")
    r = run_studio("--frames", 4, "--no-lmm", "--screenshot", tmp_path / "plain" / "shot.png", config=config)
    msgs = [e["message"] for e in r.dump["errors"]]
    assert r.rc == 1 and "Traceback" not in r.stderr and len(msgs) == 1 and "shot.png" in msgs[0], r.stderr


# -----------------------------------------------------------------------------------------------
# real keyboard input
# -----------------------------------------------------------------------------------------------

def test_keyboard_moves_the_character_xdotool(xvfb_display, studio_cache, tmp_path):
    if shutil.which("xdotool") is None:
        pytest.skip("xdotool is not installed")
    with RealKeyStudio(tmp_path, xvfb_display, studio_cache) as s:
        time.sleep(3.0)          # let it settle into its frame loop
        s.xdo("windowfocus", "--sync", s.win)
        s.xdo("mousemove", "--window", s.win, "700", "300")
        s.xdo("keydown", "w")
        time.sleep(3.5)
        s.xdo("keyup", "w")
        time.sleep(1.0)
    assert s.returncode == 0, s.stderr[-3000:]
    d = s.dump()
    pushed = [t for t in d["ticks"] if t["input"]["left_y"] > 0.5]
    assert len(pushed) > 5, "the W key never reached the input"
    start = d["ticks"][0]["roots"]["mm"]
    before = pushed[0]["roots"]["mm"]
    end = d["ticks"][-1]["roots"]["mm"]
    assert np.linalg.norm(np.subtract(before, start)) < 0.1        # standing until the key went down
    # a fixed 60 Hz tick per frame: how far it gets depends on the frame rate; it must clearly walk off
    assert np.linalg.norm(np.subtract(end, start)) > 0.25


def test_no_display_is_a_clear_error_not_a_crash():
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["PYTHONPATH"] = str(ROOT)
    r = subprocess.run([sys.executable, "-m", "app.cli", "--frames", "1"], env=env, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 2 and "no display" in r.stderr


def test_broken_database_bvh_opens_the_default_database_with_an_error(run_studio, tmp_path):
    manifest = tmp_path / "broken_manifest.json"
    manifest.write_text(json.dumps({"name": "broken", "clips": [{"file": str(CORPUS / "truncated_frame.bvh")}]}))
    r = run_studio("--frames", 10, "--no-lmm", "--manifest", manifest)
    assert r.rc == 0, r.stderr[-3000:]
    msgs = [e["message"] for e in r.dump["errors"]]
    assert len(msgs) == 1 and "truncated_frame.bvh" in msgs[0] and "default database" in msgs[0]
    assert r.dump["tick_count"] == 10


def test_a_real_drag_of_the_timeline_slider_scrubs_back_xdotool(xvfb_display, studio_cache, tmp_path):
    """Press the timeline slider near its left end and drag further left with the mouse (xdotool), the
    studio running live: the view pauses on an old tick and stays there after the release (the panel
    no longer asks dearpygui each frame whether the slider is held, nor what it holds)."""
    if shutil.which("xdotool") is None:
        pytest.skip("xdotool is not installed")
    rects = tmp_path / "rects.json"
    actions = [{"frame": 150, "do": "write_rects", "path": str(rects), "items": ["tl_slider"]}]
    with RealKeyStudio(tmp_path, xvfb_display, studio_cache, actions,
                       ["--layout", "default", "--input", "builtin:circle"]) as s:
        x0, y0, x1, y1 = s.rect(rects, "tl_slider")
        y = str(int((y0 + y1) / 2))
        s.xdo("windowfocus", "--sync", s.win)
        s.xdo("mousemove", "--window", s.win, str(int(x0 + 0.2 * (x1 - x0))), y)
        s.xdo("mousedown", "1")
        for f in (0.15, 0.1, 0.05):
            time.sleep(0.4)
            s.xdo("mousemove", "--window", s.win, str(int(x0 + f * (x1 - x0))), y)
        time.sleep(0.6)
        s.xdo("mouseup", "1")
        time.sleep(1.5)
    assert s.returncode == 0, s.stderr[-3000:]
    tl = s.dump()["final"]["timeline"]
    span = tl["newest"] - tl["oldest"]
    assert tl["paused"] and not tl["live"], tl
    assert span > 100, tl
    assert tl["tick"] <= tl["oldest"] + 0.15 * span, tl     # the slider's left end, not the newest tick
