"""The glfw player window under Xvfb: it shows the take where the camera says it should."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from viewer_testutil import ROOT, colour_mask, mask_bbox, near_any, run_view

pytestmark = pytest.mark.gui

TAKES = sorted((ROOT / "lmm" / "data" / "lafan1").glob("*.bvh.gz"))
SKELETON_ORANGE = (0.95, 0.55, 0.15)


@pytest.mark.skipif(not TAKES, reason="no shipped LAFAN1 takes")
def test_window_shows_the_take_around_the_projected_hips(xvfb_env, gl_ctx, out_dir):
    bvh = pytest.importorskip("lmm.data.bvh")
    from viewer.player import AnimationView

    take = min(TAKES, key=lambda p: p.stat().st_size)
    png = out_dir / "window_lafan1.png"
    w, h, frame = 800, 600, 400
    result = run_view([take, "--paused", "--frame", frame, "--frames", 5, "--window-screenshot", png,
                       "--width", w, "--height", h], env=xvfb_env)
    assert result.returncode == 0, result.stderr
    image = np.array(Image.open(png))
    assert image.shape[:2] == (h, w)

    anim = bvh.load(take)
    view = AnimationView(gl_ctx, anim.parents, anim.global_positions(), aspect=w / h)
    view.reset_camera(frame)
    view.set_frame(frame)
    hips = view.camera.project(view.positions[frame, :1], w, h)[0]
    view.scene.release()
    mask = colour_mask(image, SKELETON_ORANGE)
    assert near_any(mask, hips, 12), f"no skeleton pixels near the projected hips {hips}"
    background = np.array([0.17, 0.18, 0.21]) * 255
    assert np.abs(image[3, w // 2, :3] - background).max() <= 3      # sky above
    x0, y0, x1, y1 = mask_bbox(mask)
    assert (y1 - y0) > 0.25 * h and y0 > 0 and y1 < h - 1


def test_window_bad_file_exits_1_without_traceback(xvfb_env, tmp_path):
    pytest.importorskip("lmm.data.bvh")
    bad = tmp_path / "bad.bvh"
    bad.write_bytes(b"HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition Yposition Wrotation\n")
    result = run_view([bad, "--frames", 1], env=xvfb_env)
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lmm-studio view: error: bad.bvh") or "bad.bvh:" in lines[0]


SCRIPTS = Path(__file__).resolve().parent / "scripts"


def run_script(name, args, env):
    env = dict(env, PYTHONPATH=str(ROOT) + os.pathsep + env.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, str(SCRIPTS / name), *map(str, args)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=120)


def test_window_keys_and_mouse(xvfb_env):
    result = run_script("window_keys.py", [Path(__file__).resolve().parent], xvfb_env)
    assert result.returncode == 0, result.stderr
    state = json.loads(result.stdout.strip().splitlines()[-1])
    assert state == {"paused_after_space": True, "frame_after_two_rights": 2, "frame_after_shift_left": 42,
                     "faster": True, "slower": True, "follow_toggled": True, "zoomed_in": True,
                     "orbited": True, "panned": True, "resized": True, "closing": True, "run_rc": 0,
                     "style_toggled": ["capsules", "sticks"], "shadow_toggled": True}


def test_rendering_inside_dearpygui_context(xvfb_env, out_dir):
    pytest.importorskip("dearpygui")
    png = out_dir / "dearpygui_shared.png"
    png.unlink(missing_ok=True)
    result = run_script("dearpygui_shared.py", [png, Path(__file__).resolve().parent], xvfb_env)
    assert result.returncode == 0, result.stderr
    info = json.loads(result.stdout.strip().splitlines()[-1])
    assert colour_mask(np.array([[np.array(info["hips_rgba"]) * 255]]).astype(np.uint8), (0.95, 0.5, 0.1))[0, 0]
    # dearpygui kept drawing its own frames with our image in them
    shown = np.array(Image.open(png))
    assert colour_mask(shown, (0.95, 0.5, 0.1)).sum() > 200
