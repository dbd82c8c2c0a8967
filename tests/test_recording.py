"""BVH recording: round trip with our reader and pybvh (joint positions within 0.1 mm), crash safety
(a valid file after every flush; a killed recording keeps all but the last second), determinism."""
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from lmm.data import bvh
from lmm.data.inputs import builtin
from lmm.mm import MotionMatchingController
from lmm.data.recording import BVHRecorder
from lmm.runner import run_headless

ROOT = Path(__file__).resolve().parents[1]


def _record(db, features, path, seconds=4.0, source="zigzag", **kw):
    positions = []
    c = MotionMatchingController(db, features)
    with BVHRecorder(path, db, **kw) as rec:
        run_headless(c, builtin(source, seconds), seconds, recorder=rec,
                     on_step=lambda p, s: positions.append(p.global_positions[1:].astype(np.float64)))
    return np.stack(positions)


def test_round_trip_with_our_reader_and_pybvh(db, features, tmp_path):
    path = tmp_path / "run.bvh"
    expected = _record(db, features, path) * 100.0  # metres -> the file's centimetres
    anim = bvh.load(path)
    assert anim.names == db.names[1:] and anim.n_frames == len(expected)
    assert anim.frame_time == pytest.approx(1 / 60)
    ours = anim.global_positions()
    assert np.abs(ours - expected).max() < 0.01  # cm: 0.1 mm

    import pybvh
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        theirs = pybvh.read_bvh_file(path, world_up="+y")
    assert list(theirs.joint_names) == db.names[1:]
    assert np.abs(theirs.joint_positions() - expected).max() < 0.01


def test_every_flush_leaves_a_valid_file(db, features, tmp_path):
    path = tmp_path / "flush.bvh"
    c = MotionMatchingController(db, features)
    rec = BVHRecorder(path, db, flush_interval_s=1e9)  # flush only when asked
    assert bvh.load(path).n_frames == 0
    log = builtin("circle", 2.0)
    for i in range(50):
        pose, _ = c.step(log.at(i / 60), 1 / 60)
        rec.write(pose)
        if i % 17 == 16:
            rec.flush()
            assert bvh.load(path).n_frames == i + 1
    assert bvh.load(path).n_frames == 34  # the last 16 frames are still pending
    rec.close()
    assert bvh.load(path).n_frames == 50


def test_same_input_gives_byte_identical_recordings(db, features, tmp_path):
    _record(db, features, tmp_path / "a.bvh", 3.0, "random:5")
    _record(db, features, tmp_path / "b.bvh", 3.0, "random:5")
    assert (tmp_path / "a.bvh").read_bytes() == (tmp_path / "b.bvh").read_bytes()


@pytest.mark.slow
def test_killed_recording_keeps_all_but_the_last_second(tmp_path, db):
    out = tmp_path / "killed.bvh"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    cmd = [sys.executable, "-m", "app.cli", "run", "--controller", "mm", "--input", "builtin:random:1",
           "--seconds", "600", "--realtime", "--quiet", "--record", str(out)]
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while not out.exists() or out.stat().st_size == 0:  # the recorder starts right before the first tick
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline
            time.sleep(0.01)
        started = time.monotonic()
        time.sleep(4.0)
        elapsed = time.monotonic() - started
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    anim = bvh.load(out)  # a complete, valid BVH
    assert anim.names == db.names[1:]
    assert anim.n_frames >= int((elapsed - 1.0) * 60), (anim.n_frames, elapsed)
    assert np.isfinite(anim.motion).all()
    csv = out.with_name("killed.input.csv")
    from lmm.data.inputs import load_input_csv
    assert load_input_csv(csv).n_rows >= 1  # the input log is valid too
