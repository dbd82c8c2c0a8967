"""``lmm-studio view``: headless screenshots of shipped and synthetic takes, and bad files."""
import argparse
import os

import numpy as np
import pytest
from PIL import Image

from viewer_testutil import ROOT, colour_mask, mask_bbox, near_any, run_view, write_bvh

SKELETON_ORANGE = (0.95, 0.55, 0.15)   # AnimationView's default character colour
TAKES = sorted((ROOT / "lmm" / "data" / "lafan1").glob("*.bvh.gz"))
W, H = 960, 540


def no_display_env():
    env = dict(os.environ)
    env.pop("DISPLAY", None)
    env.pop("WAYLAND_DISPLAY", None)
    return env


def expected_camera(gl_ctx, path, frame, width, height):
    """The camera ``view --screenshot`` uses for ``frame``, rebuilt in-process to project joints."""
    bvh = pytest.importorskip("lmm.data.bvh")
    from viewer.player import AnimationView

    anim = bvh.load(path)
    positions = anim.global_positions()
    view = AnimationView(gl_ctx, anim.parents, positions, aspect=width / height)
    view.reset_camera(frame)
    view.set_frame(frame)
    camera = view.camera
    view.scene.release()
    return camera, positions[frame], anim


def check_framed(image, camera, pose, width, height, name):
    mask = colour_mask(image, SKELETON_ORANGE)
    hips = camera.project(pose[:1], width, height)[0]
    assert near_any(mask, hips, 12), f"{name}: no skeleton pixels near the projected hips {hips}"
    box = mask_bbox(mask)
    assert box is not None, f"{name}: no skeleton pixels"
    x0, y0, x1, y1 = box
    assert x0 > 0 and y0 > 0 and x1 < width - 1 and y1 < height - 1, f"{name}: skeleton cut off {box}"
    extent = max((x1 - x0) / width, (y1 - y0) / height)
    assert extent > 0.25, f"{name}: skeleton too small {box}"
    # near the centre of the frame
    cx, cy = (x0 + x1) / 2 / width, (y0 + y1) / 2 / height
    assert 0.25 < cx < 0.75 and 0.2 < cy < 0.8, f"{name}: skeleton off-centre {box}"


@pytest.mark.skipif(not TAKES, reason="no shipped LAFAN1 takes")
def test_screenshot_of_a_shipped_take_without_display(gl_ctx, out_dir):
    take = min(TAKES, key=lambda p: p.stat().st_size)
    png = out_dir / "view_lafan1.png"
    frame = 200
    result = run_view([take, "--screenshot", png, "--frame", frame, "--width", W, "--height", H],
                      env=no_display_env())
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    image = np.array(Image.open(png))
    assert image.shape[:2] == (H, W)
    camera, pose, _ = expected_camera(gl_ctx, take, frame, W, H)
    check_framed(image, camera, pose, W, H, take.name)


# a skeleton in other units and proportions: names unlike LAFAN1, Y up, offsets in ``unit``
CREATURE_NAMES = ["pelvis", "back", "skull", "arm_l", "hand_l", "arm_r", "hand_r", "thigh_l", "shin_l",
                  "thigh_r", "shin_r"]
CREATURE_PARENTS = [-1, 0, 1, 1, 3, 1, 5, 0, 7, 0, 9]
CREATURE_OFFSETS_M = np.array([
    [0, 0, 0], [0, 0.5, 0], [0, 0.45, 0.05], [0.3, 0.35, 0], [0.45, 0, 0], [-0.3, 0.35, 0], [-0.45, 0, 0],
    [0.15, -0.05, 0], [0, -0.6, 0.05], [-0.15, -0.05, 0], [0, -0.6, 0.05],
])


@pytest.mark.parametrize("unit_name,unit_per_m,floor_m", [("m", 1.0, 0.0), ("in", 39.37, 0.0), ("mm", 1000.0, 0.4)])
def test_screenshot_frames_other_units_and_proportions(gl_ctx, out_dir, tmp_path, unit_name, unit_per_m, floor_m):
    frames = 40
    t = np.arange(frames) / 30.0
    root_m = np.c_[3.0 + 0.8 * t, 0.72 + floor_m + 0.02 * np.sin(6 * t), -2.0 + 0.3 * t]   # walks away from the origin
    path = tmp_path / f"creature_{unit_name}.bvh"
    write_bvh(path, CREATURE_NAMES, CREATURE_PARENTS, CREATURE_OFFSETS_M * unit_per_m, root_m * unit_per_m)
    png = out_dir / f"view_creature_{unit_name}.png"
    frame = 25
    result = run_view([path, "--screenshot", png, "--frame", frame, "--width", W, "--height", H],
                      env=no_display_env())
    assert result.returncode == 0, result.stderr
    image = np.array(Image.open(png))
    camera, pose, anim = expected_camera(gl_ctx, path, frame, W, H)
    assert anim.names == CREATURE_NAMES
    check_framed(image, camera, pose, W, H, path.name)


def run_in_process(argv, capsys):
    from app.commands import view

    parser = argparse.ArgumentParser()
    view.add_arguments(parser)
    code = view.main(parser.parse_args([str(a) for a in argv]))
    captured = capsys.readouterr()
    return code, captured.err


CORPUS = sorted((ROOT / "tests" / "bvh_corpus").glob("*.bvh*"))


@pytest.mark.parametrize("bad", CORPUS, ids=[p.name for p in CORPUS])
def test_bad_files_give_one_line_errors(bad, capsys, tmp_path):
    pytest.importorskip("lmm.data.bvh")
    code, err = run_in_process([bad, "--screenshot", tmp_path / "x.png"], capsys)
    assert code == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lmm-studio view: error: ") and bad.name in lines[0], err
    assert not (tmp_path / "x.png").exists()


def test_gzip_bomb_is_refused_at_the_text_limit(capsys, tmp_path, monkeypatch):
    """A small .bvh.gz inflating to far more text than the reader accepts: refused while inflating."""
    import zlib

    bvh = pytest.importorskip("lmm.data.bvh")
    monkeypatch.setattr(bvh, "MAX_TEXT_BYTES", 2**20)
    z = zlib.compressobj(9, zlib.DEFLATED, 31)
    bomb = tmp_path / "bomb.bvh.gz"
    bomb.write_bytes(z.compress((CORPUS[0].parent / "huge_value.bvh").read_bytes().replace(b"1e308", b"1"))
                     + b"".join(z.compress(b" " * 2**20) for _ in range(16)) + z.flush())
    code, err = run_in_process([bomb, "--screenshot", tmp_path / "x.png"], capsys)
    lines = err.strip().splitlines()
    assert code == 1 and len(lines) == 1 and "bomb.bvh.gz" in lines[0] and "inflates to more than" in lines[0]
    assert not (tmp_path / "x.png").exists()


def test_bad_file_subprocess_has_no_traceback(tmp_path):
    pytest.importorskip("lmm.data.bvh")
    bad = tmp_path / "broken.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n")
    result = run_view([bad, "--screenshot", tmp_path / "x.png"], env=no_display_env())
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lmm-studio view: error: ") and "broken.bvh:" in lines[0]


def test_missing_file(capsys, tmp_path):
    code, err = run_in_process([tmp_path / "nope.bvh", "--screenshot", tmp_path / "x.png"], capsys)
    assert code == 1 and err.startswith("lmm-studio view: error: ") and "nope.bvh" in err and len(err.strip().splitlines()) == 1


def test_window_without_display_exits_2(capsys, monkeypatch, tmp_path):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    code, err = run_in_process([tmp_path / "whatever.bvh"], capsys)
    assert code == 2 and "--screenshot" in err and "Traceback" not in err


def test_frame_out_of_range(capsys, tmp_path):
    pytest.importorskip("lmm.data.bvh")
    path = tmp_path / "short.bvh"
    write_bvh(path, CREATURE_NAMES, CREATURE_PARENTS, CREATURE_OFFSETS_M, np.zeros((3, 3)) + [0, 1, 0])
    code, err = run_in_process([path, "--screenshot", tmp_path / "x.png", "--frame", 7], capsys)
    assert code == 2 and "3 frames" in err


@pytest.mark.skipif(not TAKES, reason="no shipped LAFAN1 takes")
def test_screenshot_styles_and_shadow(out_dir):
    pytest.importorskip("lmm.data.bvh")
    take = min(TAKES, key=lambda p: p.stat().st_size)
    images = {}
    for flags in ([], ["--style", "sticks"], ["--no-shadow"]):
        png = out_dir / f"view_style{'_'.join(flags).replace('--', '_')}.png"
        # a subprocess: an in-process screenshot would leave its own GL context current
        result = run_view([take, "--screenshot", png, "--frame", 200, "--width", 480, "--height", 270, *flags],
                          env=no_display_env())
        assert result.returncode == 0, result.stderr
        images[" ".join(flags)] = np.array(Image.open(png)).astype(int)
    body = {k: colour_mask(v.astype(np.uint8), SKELETON_ORANGE).sum() for k, v in images.items()}
    assert body[""] > 2 * body["--style sticks"] > 0            # capsules are a body, sticks are thin
    assert abs(body[""] - body["--no-shadow"]) < 0.005 * body[""]   # the shadow only touches the ground...
    darker = images[""].sum(axis=-1) < images["--no-shadow"].sum(axis=-1) - 30
    assert darker.sum() > 200                                  # ...and it is there by default


def test_unknown_style_is_a_usage_error(tmp_path):
    result = run_view([tmp_path / "x.bvh", "--style", "blobs", "--screenshot", tmp_path / "x.png"],
                      env=no_display_env())
    assert result.returncode == 2 and "--style" in result.stderr and "Traceback" not in result.stderr


# -- the screenshot target: written whole or not at all, a bad target is one line -------------------

@pytest.mark.parametrize("target", ["file_as_folder", "a_folder"])
def test_screenshot_to_an_unwritable_target_is_one_line(capsys, tmp_path, target):
    (tmp_path / "plain").write_text("not a folder")
    out = {"file_as_folder": tmp_path / "plain" / "x.png", "a_folder": tmp_path}[target]
    code, err = run_in_process([_good_bvh(tmp_path), "--screenshot", out], capsys)
    lines = err.strip().splitlines()
    assert code == 1 and len(lines) == 1 and lines[0].startswith("lmm-studio view: error: ") and str(out) in lines[0], err
    assert "Traceback" not in err


def test_screenshot_to_a_read_only_or_full_disk_leaves_no_file(capsys, tmp_path, monkeypatch):
    import errno

    import lmm.data.atomic as png      # the one atomic writer under lmm.reporting.write_png

    out = tmp_path / "shot.png"
    real_open = png.os.open

    def read_only(path, *a, **k):
        raise OSError(errno.EROFS, "Read-only file system")
    monkeypatch.setattr(png.os, "open", read_only)
    code, err = run_in_process([_good_bvh(tmp_path), "--screenshot", out], capsys)
    assert code == 1 and "shot.png" in err and "Read-only" in err and len(err.strip().splitlines()) == 1
    monkeypatch.setattr(png.os, "open", real_open)

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(png.os, "fsync", full)
    code, err = run_in_process([_good_bvh(tmp_path), "--screenshot", out], capsys)
    assert code == 1 and "shot.png" in err and "No space" in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["good.bvh"]      # no PNG, no temporary file
    monkeypatch.undo()
    code, err = run_in_process([_good_bvh(tmp_path), "--screenshot", out], capsys)
    assert code == 0 and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_screenshot_size_is_bounded(capsys, tmp_path):
    code, err = run_in_process([_good_bvh(tmp_path), "--screenshot", tmp_path / "x.png", "--width", "100000"],
                               capsys)
    assert code == 2 and "--width" in err and not (tmp_path / "x.png").exists()


def _good_bvh(tmp_path):
    """A tiny valid BVH (two joints, three frames)."""
    path = tmp_path / "good.bvh"
    if not path.exists():
        path.write_text("HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition "
                        "Zrotation Yrotation Xrotation\n JOINT Spine\n {\n  OFFSET 0 10 0\n  CHANNELS 3 Zrotation "
                        "Yrotation Xrotation\n  End Site\n  {\n   OFFSET 0 10 0\n  }\n }\n}\nMOTION\nFrames: 3\n"
                        "Frame Time: 0.0333333\n" + "0 90 0 0 0 0 0 0 0\n" * 3)
    return path
