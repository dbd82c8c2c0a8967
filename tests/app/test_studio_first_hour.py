"""Issue 35's studio items, driven with real keys and mouse (xdotool) on the real studio under Xvfb:
a failed file load by an absolute path typed in the file dialog is on screen at once and leaves the keys
working; the wheel over the 3D view zooms without scrolling its toolbar away."""
import json
import shutil
import time

import pytest

from studio_testutil import RealKeyStudio

pytestmark = pytest.mark.gui

W, H = 1280, 800
DIALOG_W, DIALOG_H = 700, 420            # app.dialogs: every file dialog's size, centred in the window
ERROR_TITLE = (255, 140, 120)            # app.panels.errors: the error title's colour


def _grab(display):
    from PIL import ImageGrab

    return ImageGrab.grab(xdisplay=display).convert("RGB")


def _window_origin(s):
    geo = s.xdo("getwindowgeometry", "--shell", s.win).stdout
    vals = dict(line.split("=", 1) for line in geo.split() if "=" in line)
    return int(vals["X"]), int(vals["Y"])


def _has_colour(img, colour, box) -> int:
    import numpy as np
    rgb = np.asarray(img.crop(box).convert("RGB"), dtype=np.int64).reshape(-1, 3)
    return int((np.abs(rgb - np.asarray(colour[:3])).max(axis=1) <= 30).sum())


def test_failed_load_by_absolute_path_is_shown_and_keys_work_and_wheel_zooms(xvfb_display, studio_cache,
                                                                               tmp_path):
    if shutil.which("xdotool") is None:
        pytest.skip("xdotool is not installed")
    pytest.importorskip("PIL.ImageGrab")
    missing = "/nowhere_h/take_mm.bvh"    # short: dearpygui takes about one typed character a frame
    rects = tmp_path / "rects.json"
    actions = [{"frame": 15, "do": "write_rects", "path": str(rects), "items": ["vp_drawlist", "vp_inspect",
                                                                              "tun_save_preset"]},
               {"frame": 16, "do": "dialog_reference"}]
    args = ["--layout", "default", "--width", str(W), "--height", str(H)]
    with RealKeyStudio(tmp_path, xvfb_display, studio_cache, actions, args) as s:
        xdo, win = s.xdo, s.win
        view = s.rect(rects, "vp_drawlist", settle_s=1.5)
        toolbar = s.rect(rects, "vp_inspect", settle_s=0)
        xdo("windowfocus", "--sync", win)
        # the dialog's File Name field and OK button (ImGuiFileDialog's layout at this size)
        dx, dy = (W - DIALOG_W) // 2, (H - DIALOG_H) // 2
        xdo("mousemove", "--window", win, str(dx + 300), str(dy + 379))
        xdo("click", "1")
        time.sleep(0.5)
        xdo("type", "--delay", "150", missing)
        time.sleep(2.0)
        xdo("mousemove", "--window", win, str(dx + 19), str(dy + 403))
        xdo("click", "1")
        time.sleep(1.0)
        ox, oy = _window_origin(s)
        shot = _grab(xvfb_display)
        shot.save(tmp_path / "error_shown.png")
        # the error dialog (centred, 560 x 190) is drawn: its red title text is on screen
        box = (ox + W // 2 - 280, oy + H // 2 - 95, ox + W // 2 + 280, oy + H // 2 + 95)
        assert _has_colour(shot, ERROR_TITLE, box) > 10, f"no error dialog on screen ({tmp_path / 'error_shown.png'})"
        # W moves the character with the message still shown
        t_w = time.time()
        xdo("keydown", "w")
        time.sleep(1.5)
        xdo("keyup", "w")
        time.sleep(0.3)
        # the wheel over the 3D view (away from the dialog) zooms; the toolbar stays where it was
        xdo("mousemove", "--window", win, str(int(view[0] + 40)), str(int(view[1] + 30)))
        before = _grab(xvfb_display).crop((ox + int(toolbar[0]), oy + int(toolbar[1]),
                                           ox + int(toolbar[2]), oy + int(toolbar[3])))
        for _ in range(6):
            xdo("click", "5")
            time.sleep(0.15)
        time.sleep(1.0)
        after = _grab(xvfb_display).crop((ox + int(toolbar[0]), oy + int(toolbar[1]),
                                          ox + int(toolbar[2]), oy + int(toolbar[3])))
        after.save(tmp_path / "toolbar_after_wheel.png")
        # OK on the error; Save preset... and OK on its default name, twice: the second asks first
        xdo("mousemove", "--window", win, str(W // 2 - 280 + 45), str(H // 2 - 95 + 94))
        xdo("click", "1")
        time.sleep(0.5)
        save = s.rect(rects, "tun_save_preset", settle_s=0)
        preset = tmp_path / "cfg" / "presets" / "tuning.json"
        for attempt in range(2):
            xdo("mousemove", "--window", win, str(int(save[0] + 20)), str(int(save[1] + 8)))
            xdo("click", "1")
            time.sleep(1.0)
            xdo("mousemove", "--window", win, str(dx + 19), str(dy + 403))
            xdo("click", "1")
            time.sleep(1.0)
            if attempt == 0:
                assert preset.is_file(), "the preset was not saved as presets/tuning.json"
                preset.write_text("{}")
        _grab(xvfb_display).save(tmp_path / "replace_question.png")
        # the window made larger: the panels follow it
        xdo("windowsize", win, str(W + 240), str(H + 100))
        time.sleep(2.5)
        _grab(xvfb_display).save(tmp_path / "resized.png")
    assert s.returncode == 0, s.stderr[-3000:]
    d = s.dump()
    # the path typed is the one read (no current folder in front of it), reported once
    errors = [e for e in d["errors"] if e["title"] == "Reference BVH"]
    assert len(errors) == 1 and f"'{missing}'" in errors[0]["message"], d["errors"]
    assert str(tmp_path) not in errors[0]["message"]
    assert errors[0]["time"] < t_w
    assert errors[0]["time"] < t_w            # W moved with the error shown (it was dismissed later)
    # the second save asks before replacing; unanswered, the file is as it was
    assert d["final"]["dialog"] == {"title": "Save tuning preset", "shown": True}, d["final"]["dialog"]
    assert preset.read_text() == "{}"
    assert not (tmp_path / "presetjson.json").exists() and not (tmp_path / "preset.json").exists()
    shown = [w for w in d["final"]["windows"].values() if w["shown"]]
    assert abs(max(w["pos"][0] + w["size"][0] for w in shown) - (W + 240)) <= 3, shown
    assert abs(max(w["pos"][1] + w["size"][1] for w in shown) - (H + 100)) <= 3, shown
    # a script steps one tick a frame, far slower than real time here: the menu bar says so
    assert d["final"]["menu"]["behind"].startswith("behind real time: 0."), d["final"]["menu"]
    assert any(t["input"]["left_y"] for t in d["ticks"]), "W did not move the character after the error"
    assert before.tobytes() == after.tobytes(), "the wheel scrolled the 3D view's toolbar"
    assert abs(d["final"]["viewport"]["camera"]["distance"] - 4.6) > 0.1, d["final"]["viewport"]["camera"]


def test_sideways_run_framing_ragdoll_and_ghost_after_layout_switch(run_studio, lmm_weights):
    """Zoom-independent framing: during a sideways run with Follow on (side by side), the camera's target
    stays within a third of the view's half-height of the inspected character; the ragdoll is not drawn
    by default (the Physics window is hidden); a candidate's ghost goes with the Database window a
    layout switch hides."""
    from app.panels.viewport_camera import focus_radius

    script = [{"frame": 2, "do": "key_down", "key": "ctrl"}, {"frame": 2, "do": "key_down", "key": "d"},
              {"frame": 150, "do": "capture", "label": "side"},
              {"frame": 151, "do": "key_up", "key": "d"}, {"frame": 151, "do": "key_up", "key": "ctrl"},
              {"frame": 152, "do": "click_candidate", "row": 0},
              {"frame": 160, "do": "capture", "label": "ghost"},
              {"frame": 161, "do": "layout", "name": "default"},
              {"frame": 165, "do": "capture", "label": "after"}]
    args = ["--frames", 168, "--layout", "default"] + (["--weights", lmm_weights] if lmm_weights else ["--no-lmm"])
    r = run_studio(*args, script=script)
    assert r.rc == 0, r.stderr[-3000:]
    labels = r.dump["labels"]
    vp = labels["side"]["panels"]["viewport"]
    inspected = "mm"
    root = [a + b for a, b in zip(vp["roots"][inspected], vp["offsets"][inspected])]
    target, cam = vp["camera"]["target"], vp["camera"]
    moved = abs(vp["roots"][inspected][0]) + abs(vp["roots"][inspected][2])
    assert moved > 2.0, vp["roots"]                    # it did run
    # the follow's lag behind a 2 m/s sideways run (blend 0.12 a frame at 60 ticks/s) is about 0.25 m
    off_centre = ((root[0] - target[0]) ** 2 + (root[2] - target[2]) ** 2) ** 0.5
    assert off_centre < focus_radius(cam["distance"], 45.0) + 0.3, (off_centre, root, target)
    assert vp["ragdoll"] is None and "ragdoll" not in vp["labels"]
    assert labels["ghost"]["panels"]["viewport"]["previews"], "the candidate click showed no ghost"
    # the Database window the click showed opens below the 3D view, not over it or Tuning
    from app.layout_files import OPENS_AT

    db_window = labels["ghost"]["panels"]["windows"]["database"]
    x, y, w, h = OPENS_AT["default"]["database"]
    assert db_window["shown"] and db_window["pos"] == [x, y] and db_window["size"] == [w, h], db_window
    assert labels["after"]["panels"]["viewport"]["previews"] == [], "the ghost stayed after the layout switch"
