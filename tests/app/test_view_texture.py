"""The 3D view drawn into dearpygui's own texture (app.gl_texture), under Xvfb.

The texture finder runs in a subprocess of its own (dearpygui is one global context per process); the
studio runs once each way, and its picture is compared with the readback path's."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from studio_testutil import ROOT

pytestmark = pytest.mark.gui

FINDER = textwrap.dedent("""
    import json, numpy as np
    import dearpygui.dearpygui as dpg
    import moderngl
    from app.gl_texture import SharedTexture, marker_image, texture_names

    W, H = 120, 80
    dpg.create_context()
    dpg.add_texture_registry(tag="reg")
    with dpg.window(width=400, height=300):
        dpg.add_drawlist(W, H, tag="dl")
    dpg.create_viewport(width=400, height=300, vsync=False)
    dpg.setup_dearpygui()
    dpg.show_viewport()
    dpg.render_dearpygui_frame()
    gl = moderngl.create_context()
    names, why = texture_names()
    out = {"why": why}
    bg = (0.13, 0.14, 0.17)
    # two textures of the same size, made on the same frame: the marker tells them apart
    mine, other = marker_image(W, H, bg, 1), marker_image(W, H, bg, 2)
    finders = {}
    for tag, img in (("mine", mine), ("other", other)):
        dpg.add_static_texture(W, H, img.ravel(), tag=tag, parent="reg")
        finders[tag] = SharedTexture(gl, names, W, H, img)
    # a finder whose marker is in no texture: never found
    lost = SharedTexture(gl, names, W, H, marker_image(W, H, bg, 3))
    out["before_frame"] = finders["mine"].find()
    dpg.draw_image("mine", (0, 0), (W, H), parent="dl", uv_min=(0, 1), uv_max=(1, 0))
    dpg.render_dearpygui_frame()
    out["found"] = {t: f.find() for t, f in finders.items()}
    out["names"] = {t: f.texture.glo for t, f in finders.items()}
    out["lost"] = [lost.find() for _ in range(3)]
    # draw into "mine" through its framebuffer: what dearpygui shows is what was drawn
    f = finders["mine"]
    f.fbo.use()
    f.fbo.clear(0.2, 0.6, 0.3, 1.0)
    gl.detect_framebuffer(0).use()
    dpg.render_dearpygui_frame()
    out["pixel"] = np.frombuffer(f.texture.read(), np.uint8)[:4].tolist()
    glo = f.texture.glo
    f.release()
    out["alive_after_release"] = glo in names.alive(glo)
    print(json.dumps(out))
    dpg.destroy_context()
""")


def test_shared_texture_finds_dearpygui_texture_by_size_and_marker(xvfb_display, tmp_path):
    env = dict(os.environ, DISPLAY=xvfb_display, PYTHONPATH=str(ROOT), LP_NUM_THREADS="0")
    proc = subprocess.run([sys.executable, "-c", FINDER], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr[-3000:]
    import json

    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["why"] == ""
    assert out["before_frame"] is False              # dearpygui makes the texture on the next frame
    assert out["found"] == {"mine": True, "other": True}
    assert out["names"]["mine"] != out["names"]["other"]
    assert out["lost"] == [False, False, False]
    assert out["pixel"] == [51, 153, 76, 255]         # 0.2, 0.6, 0.3 as 8-bit
    assert out["alive_after_release"]                # the wrapper's release leaves dearpygui's texture


def _view_pixels(dump: dict, shot):
    """The 3D view's pixels in a screenshot, from the window rectangle in the state dump."""
    from PIL import Image

    win = dump["final"]["windows"]["viewport"]
    (x, y), (w, h) = win["pos"], win["size"]
    img = np.asarray(Image.open(shot).convert("RGB"), dtype=np.int16)
    # the image area below the toolbar and the overlay line, inside the window's border
    return img[y + 120:y + h - 10, x + 10:x + w - 10]


def test_studio_draws_the_view_into_dearpygui_texture_one_frame_sooner(run_studio, tmp_path):
    """The studio on Xvfb takes the direct path; its picture after N frames is the readback path's after
    N + 1 (dearpygui's raw texture shows the array it was given one frame late), and not the
    readback path's after N."""
    common = ("--input", "builtin:zigzag", "--no-lmm", "--no-physics", "--layout", "default")
    direct = run_studio("--frames", 40, *common, "--screenshot", tmp_path / "direct.png")
    assert direct.rc == 0, direct.stderr[-3000:]
    vp = direct.dump["final"]["viewport"]
    assert vp["view_path"] == "direct" and vp["readback_why"] is None
    views = {}
    for frames in (40, 41):
        r = run_studio("--frames", frames, *common, "--readback-3d", "--screenshot", tmp_path / f"rb{frames}.png")
        assert r.rc == 0, r.stderr[-3000:]
        assert r.dump["final"]["viewport"]["view_path"] == "readback"
        assert r.dump["final"]["viewport"]["readback_why"] == "--readback-3d"
        views[frames] = _view_pixels(r.dump, tmp_path / f"rb{frames}.png")
    mine = _view_pixels(direct.dump, tmp_path / "direct.png")
    assert mine.std() > 10.0                          # a scene, not the background alone

    def changed(a, b):
        return float(np.mean(np.abs(a - b).max(axis=2) > 8))

    same_tick, next_tick = changed(mine, views[40]), changed(mine, views[41])
    # the character and its labels move between frames; the same picture differs only where a label's
    # text changes
    assert next_tick < 0.02, (next_tick, same_tick)
    assert same_tick > 4 * next_tick + 0.01, (next_tick, same_tick)


def test_a_paused_untouched_view_is_not_drawn_again(run_studio, tmp_path):
    """Paused at frame 30, the 3D view is not rendered again (its texture keeps the picture) until the
    inspected character changes (frame 60) or a tick is stepped (frame 70, shown at 71), and the
    panels' numbers are worked out once per tick and view, not every paused frame."""
    script = [{"frame": 30, "do": "pause"},
              {"frame": 40, "do": "screenshot", "path": str(tmp_path / "p40.png")},
              {"frame": 55, "do": "screenshot", "path": str(tmp_path / "p55.png")},
              {"frame": 60, "do": "inspect", "controller": "lmm"},
              {"frame": 70, "do": "step", "n": 1},
              {"frame": 80, "do": "screenshot", "path": str(tmp_path / "p80.png")}]
    r = run_studio("--frames", 90, "--input", "builtin:zigzag", "--no-physics", "--layout", "default", script=script)
    assert r.rc == 0, r.stderr[-3000:]
    if r.dump["controllers"] != ["mm", "lmm"]:
        pytest.skip("needs the LMM character (shipped weights)")
    rendered = [i for i, f in enumerate(r.dump["frames"]) if f["ms"]["render"] > 0]
    assert [i for i in rendered if i >= 30] == [30, 60, 71]
    assert r.dump["final"]["viewport"]["renders"] == len(rendered)
    assert set(range(30)) <= set(rendered)
    # the panels' numbers are kept from one paused frame to the next (checked against a new working-out
    # on every such frame: run_studio asserts no mismatch), except the latent maps' easing colour range
    prep = r.dump["prepared"]
    assert prep["checked"] and prep["mismatches"] == []
    for key in ("viewport", "features", "search", "timeline", "candidates"):
        assert prep["kept"].get(key, 0) >= 50, prep      # 60 paused frames, less a new tick and inspect
    assert "latent" not in prep["kept"], prep
    views = {n: _view_pixels(r.dump, tmp_path / f"p{n}.png") for n in (40, 55, 80)}
    assert views[40].std() > 10.0
    assert np.array_equal(views[40], views[55])
    assert np.mean(np.abs(views[55] - views[80]).max(axis=2) > 8) > 0.02


def test_a_texture_that_is_never_found_falls_back_to_the_readback(xvfb_display, studio_cache, tmp_path):
    """When dearpygui's texture is not found (here: a finder that never finds), the view is read back
    after 3 frames, the dump says why, and the picture is there."""
    import json

    code = ("import sys, app.gl_texture as g\n"
            "def never(self):\n"
            "    self.tries += 1\n"
            "    return False\n"
            "g.SharedTexture.find = never\n"
            "from app.cli import main\n"
            "sys.exit(main(sys.argv[1:]))\n")
    dump, shot = tmp_path / "dump.json", tmp_path / "shot.png"
    env = dict(os.environ, DISPLAY=xvfb_display, LMM_STUDIO_CONFIG=str(tmp_path / "config"),
               LMM_STUDIO_CACHE=str(studio_cache), PYTHONPATH=str(ROOT), LP_NUM_THREADS="0")
    proc = subprocess.run([sys.executable, "-c", code, "--frames", "30", "--input", "builtin:zigzag", "--no-lmm",
                           "--no-physics", "--layout", "default", "--no-gamepads", "--screenshot", str(shot),
                           "--dump-state", str(dump)], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=150)
    assert proc.returncode == 0, proc.stderr[-3000:]
    d = json.loads(dump.read_text())
    vp = d["final"]["viewport"]
    assert vp["view_path"] == "readback"
    assert vp["readback_why"] == "dearpygui's texture not found in 3 frames"

    assert _view_pixels(d, shot).std() > 10.0


def test_a_resized_view_shows_its_picture_on_the_frame_of_the_resize(run_studio, tmp_path):
    """A layout switch resizes the view: dearpygui makes the new texture during that frame from the
    picture read back once, so no frame shows an empty view (before, the frame after the switch showed
    the background)."""
    script = [{"frame": 30, "do": "layout", "name": "compare"},
              *({"frame": f, "do": "screenshot", "path": str(tmp_path / f"s{f}.png")} for f in (30, 31, 32))]
    r = run_studio("--frames", 40, "--input", "builtin:zigzag", "--no-physics", script=script)
    assert r.rc == 0, r.stderr[-3000:]
    vp = r.dump["final"]["viewport"]
    assert vp["view_path"] == "direct"
    for f in (30, 31, 32):
        assert _view_pixels(r.dump, tmp_path / f"s{f}.png").std() > 10.0, f


def test_the_view_follows_a_window_resize_on_the_next_frames(run_studio, tmp_path):
    """The viewport asks for its window's size only when dearpygui reports a resize (or every 60 frames):
    a window resized at frame 30 of a 40-frame run must still give a view of the new size, and a
    picture in it."""
    rects = tmp_path / "rects.json"
    script = [{"frame": 30, "do": "window_size", "window": "viewport", "width": 640, "height": 420},
              {"frame": 38, "do": "write_rects", "path": str(rects), "items": ["vp_drawlist"]},
              {"frame": 38, "do": "screenshot", "path": str(tmp_path / "s.png")}]
    r = run_studio("--frames", 40, "--input", "builtin:zigzag", "--no-physics", script=script)
    assert r.rc == 0, r.stderr[-3000:]
    vp = r.dump["final"]["viewport"]
    x0, y0, x1, y1 = json.loads(rects.read_text())["vp_drawlist"]
    assert vp["size"][0] == 640 - 16
    assert [x1 - x0, y1 - y0] == vp["size"]        # the drawing was given the new size
    assert vp["render_size"] == vp["size"]
    assert _view_pixels(r.dump, tmp_path / "s.png").std() > 10.0
