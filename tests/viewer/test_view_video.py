"""``lmm-studio view FILE --video OUT.mp4`` (app/video.py): the frames the headless renderer draws, as an mp4 that
another decoder (PyAV when installed, else ffmpeg's own count) reads back; the missing extra is one line."""
import sys

import numpy as np
import pytest

from viewer_testutil import ROOT, run_view


def test_frames_are_chosen_by_time():
    from app.video import video_frames

    # a 60 fps file shown at 60 fps: one file frame a video frame; at 30 fps every other one
    assert list(video_frames(100, 1 / 60, 0, 60.0, 0.5)) == list(range(30))
    assert list(video_frames(100, 1 / 60, 10, 30.0, 0.5)) == list(range(10, 40, 2))
    assert list(video_frames(5, 1 / 30, 0, 30.0, None)) == [0, 1, 2, 3, 4]          # to the end, no further
    assert list(video_frames(5, 1 / 30, 0, 30.0, 10.0))[-1] == 4


def test_a_missing_video_extra_is_one_line(monkeypatch):
    from app import video

    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)
    from lmm.data.motion_files import MissingExtra

    with pytest.raises(MissingExtra) as e:
        video.require_imageio_ffmpeg()
    assert "\n" not in str(e.value) and "'.[video]'" in str(e.value)


def test_view_writes_an_mp4_another_decoder_reads(gl_ctx, tmp_path):
    pytest.importorskip("imageio_ffmpeg")
    take = ROOT / "lmm/data/lafan1/multipleActions1_subject1.bvh.gz"
    out = tmp_path / "clip.mp4"
    r = run_view([take, "--video", out, "--seconds", "1", "--width", "161", "--height", "120", "--frame", "100"])
    assert r.returncode == 0, r.stderr
    assert "saved 30 frames" in r.stdout and "160x120" in r.stdout
    try:
        import av
    except ImportError:
        import imageio_ffmpeg
        assert imageio_ffmpeg.count_frames_and_secs(str(out))[0] == 30
        return
    with av.open(str(out)) as c:
        stream = c.streams.video[0]
        assert (stream.codec_context.name, stream.width, stream.height) == ("h264", 160, 120)
        assert float(stream.average_rate) == pytest.approx(30.0, rel=1e-3)
        images = [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]
    assert len(images) == 30
    # the character (orange) is in every frame and moves: the frames differ
    orange = [np.count_nonzero((im[..., 0] > 150) & (im[..., 2] < 100)) for im in images]
    assert min(orange) > 20, orange
    assert np.abs(images[0].astype(int) - images[-1].astype(int)).mean() > 0.5


def _two_controller_session(path, seconds: float, fps: int = 60) -> None:
    """A session of MM and LMM side by side on builtin:circle, written through the session API (``run`` records
    one controller; the studio records both)."""
    from lmm.data.build import load_or_build
    from lmm.data.inputs import open_input
    from lmm.factory import make_controller
    from lmm.features import build_features
    from lmm.runner import step_controllers
    from lmm.session.player import SessionRecorder
    from lmm.session.writer import SessionWriter
    from lmm.tuning import Tuning

    db, _ = load_or_build(None)
    features = build_features(db)
    tuning = Tuning()
    tuning.name_database_entries({ch.name: float(w) for ch, w in zip(features.layout, features.weights)},
                                 db.tag_names)
    controllers = {kind: make_controller(kind, db, features, tuning) for kind in ("mm", "lmm")}
    writer = SessionWriter(path, fps=fps, db=db, manifest=None, controllers=controllers, tuning=tuning,
                           start={"input": "builtin:circle", "seconds": seconds, "reset": {}})
    recorder = SessionRecorder(tuning, controllers, [], writer)
    source = open_input("builtin:circle", seconds)
    for c in controllers.values():
        c.reset()
    for tick in range(int(round(seconds * fps))):
        inp = source(tick / fps)
        recorder.before_step(tick, inp)
        poses, _, _ = step_controllers(controllers, inp, 1.0 / fps)
        recorder.after_step(tick, poses)
    recorder.close()


def test_a_session_video_draws_every_character_with_the_tick_and_costs(gl_ctx, tmp_path, monkeypatch, capsys):
    pytest.importorskip("imageio_ffmpeg")
    av = pytest.importorskip("av")
    from app.cli import main
    from app.session_video import overlay_text, replay_session

    monkeypatch.setenv("LMM_STUDIO_CACHE", str(ROOT / ".cache/lmm-studio"))
    session = tmp_path / "two.lmmsession"
    _two_controller_session(session, 1.0)
    motion = replay_session(session)
    assert motion.controllers == ["mm", "lmm"] and len(motion.positions["lmm"]) == 60
    assert overlay_text(motion, 30).startswith("tick 30  0.50 s") and "lmm: frame" in overlay_text(motion, 30)
    out = tmp_path / "two.mp4"
    assert main(["view", str(session), "--video", str(out), "--width", "320", "--height", "180"]) == 0
    assert "saved 60 frames" in capsys.readouterr().out
    with av.open(str(out)) as c:
        images = [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]
    assert len(images) == 60
    im = images[45].astype(int)
    # MM orange, LMM green: green pixels in a median frame are the second body (a one-character session's
    # video has at most ~80 at this size, from the ground's axis gizmo; with LMM drawn, 116 to 443)
    orange = [int(((f[..., 0] > 150) & (f[..., 2] < 100)).sum()) for f in images]
    green = [int(((f[..., 1] > 140) & (f[..., 0] < 150) & (f[..., 2] < 110)).sum()) for f in images]
    assert np.median(orange) > 100 and np.median(green) > 100, (np.median(orange), np.median(green))
    band = im[:8]
    assert band.mean() < 60 and (im[:20] > 200).any()                               # the overlay's band and text


@pytest.mark.parametrize("name", ["FBX/huesitos.fbx", "FBX/animation_with_skeleton.fbx"])
def test_real_animated_files_play_in_view(name, gl_ctx, tmp_path):
    """Files nobody here wrote (Debian's assimp-testmodels) render headless: the body is drawn. (Its third
    animated skeleton, glTF2/simple_skin, has its two joints at one point: it reads and plays, and draws nothing.)"""
    from pathlib import Path

    path = Path("/usr/share/assimp/models") / name
    if not path.exists():
        pytest.skip("Debian's assimp-testmodels is not installed (apt-get install assimp-testmodels)")
    pytest.importorskip("pygltflib")
    if name.endswith(".fbx"):
        pytest.importorskip("ufbx")
    out = tmp_path / "shot.png"
    r = run_view([path, "--screenshot", out, "--frame", "5", "--width", "320", "--height", "180"])
    assert r.returncode == 0, r.stderr
    from PIL import Image
    im = np.asarray(Image.open(out).convert("RGB")).astype(int)
    assert ((im[..., 0] > 150) & (im[..., 2] < 100)).sum() > 100          # the orange body
