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
