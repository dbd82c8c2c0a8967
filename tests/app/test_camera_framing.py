"""The 3D view's follow framing (app.panels.viewport_camera), headless: the inspected character stays in
the middle of the picture however far apart the figures drift and however close the camera is."""
import math

import numpy as np

import viewer
from app.panels.viewport_camera import CameraControl, drawn_root, focus_radius, pull_towards


def _control():
    return CameraControl(viewer, dpg=None, orbit_camera=lambda d: None, drawlist="", follow_checkbox="")


def test_follow_keeps_the_inspected_character_near_the_middle_when_zoomed_in():
    cam = _control()
    cam.camera.distance = 1.5                                    # zoomed in
    inspected, other = [0.0, 0.9, 0.0], [4.0, 0.9, 0.0]          # a sideways run: the figures 4 m apart
    for _ in range(200):
        cam.aim(0.0, [np.array(inspected), np.array(other)], live=True, focus=inspected)
    t = cam.camera.target
    r = focus_radius(1.5, cam.camera.fov_y_deg)
    assert math.hypot(t[0] - inspected[0], t[2] - inspected[2]) <= r + 1e-6
    assert r == 1.5 * math.tan(math.radians(cam.camera.fov_y_deg) / 2) / 3
    # without a focus the target is the mean (2 m from the inspected one: off the picture at 1.5 m)
    free = _control()
    for _ in range(200):
        free.aim(0.0, [np.array(inspected), np.array(other)], live=True)
    assert abs(free.camera.target[0] - 2.0) < 1e-3


def test_pull_towards_and_drawn_root():
    assert pull_towards([0.5, 1.0, 0.0], [0.0, 0.0, 0.0], 1.0) == [0.5, 1.0, 0.0]    # near enough: as it is
    p = pull_towards([3.0, 1.0, 4.0], [0.0, 0.0, 0.0], 1.0)
    assert np.allclose(p, [0.6, 1.0, 0.8])
    drawn = {"roots": {"lmm": [1.0, 0.9, 2.0]}, "offsets": {"lmm": [1.6, 0.0, 0.0]}}
    assert drawn_root(drawn, "lmm") == [2.6, 0.9, 2.0] and drawn_root(drawn, "mm") is None


def test_speed_axis_floor():
    from app.panels.timeline import speed_axis_top

    assert speed_axis_top(2.5e-45) == 1.0 and speed_axis_top(0.0) == 1.0      # standing: 0..1 m/s, not noise
    assert speed_axis_top(3.5) == 4.0 and speed_axis_top(0.9) == 1.0


def test_real_time_ratio():
    from app.realtime import RealTimeRatio

    r = RealTimeRatio(window_s=3.0)
    for _ in range(30):
        r.add(0.1, 0.1, playing=True)
    assert r.note() == ""                                           # in real time: nothing said
    for _ in range(40):
        r.add(0.1, 0.04, playing=True)                              # 4 ticks' worth of 10 a frame
    assert abs(r.ratio() - 0.4) < 1e-9 and r.note() == "behind real time: 0.40x"
    r.add(0.1, 0.0, playing=False)                                  # paused: measured again
    assert r.ratio() is None and r.note() == ""


def test_file_dialog_paths():
    from app.dialogs import chosen_path

    here = {"current_path": "/work/main"}
    # an absolute path typed in File Name is taken as it is (dearpygui's own join put the folder in front)
    assert chosen_path({**here, "file_name": "/data/take.bvh",
                        "file_path_name": "/work/main//data/take.bvh"}, (".bvh",)) == "/data/take.bvh"
    assert chosen_path({**here, "file_name": "~/t.bvh"}).startswith("/") and "~" not in chosen_path(
        {**here, "file_name": "~/t.bvh"})
    assert chosen_path({**here, "file_name": "tuning"}, (".json",)) == "/work/main/tuning.json"
    assert chosen_path({**here, "file_name": "a.gz"}, (".bvh",)) == "/work/main/a.gz"
