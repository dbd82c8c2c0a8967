"""The studio's session without a display: ticks on the tick worker, recording (paths, never overwriting, a full
disk), replaying a recorded input, the projected frame and latents it fills, the reference clip."""
import os
import numpy as np
import pytest
from app.recording import RecordingResult, recording_paths
from app.reference_clip import load_reference_clip
from app.session import Session
from lmm.controller import InputState
from lmm.factory import make_controllers
from lmm.tuning import Tuning
from studio_testutil import CORPUS


def test_recording_paths():
    p = recording_paths("/x/take.bvh", ("mm", "lmm"))
    assert p["mm"].name == "take_mm.bvh" and p["lmm"].name == "take_lmm.bvh" and p["input"].name == "take_input.csv"
    assert recording_paths("/x/run", ("lmm",))["lmm"].name == "run.bvh"


def test_tick_worker_works_out_the_newest_ghost_pose_trajectory_and_query(dbf):
    from app.tick_worker import TickWorker

    db, features = dbf
    tuning = Tuning()
    controllers, _ = make_controllers(db, features, tuning, with_lmm=False)
    worker = TickWorker(Session(db, features, tuning, controllers))
    try:
        worker.submit([InputState(left_y=1.0)] * 8)
        ticks = [t for t, _ in worker.wait()]
    finally:
        worker.close()
    assert len(ticks) == 8

    def pending(tick, name="matched_pose_positions"):    # the lazy field still holds its function
        return callable(tick.snapshots["mm"].__dict__["_lazy_" + name])

    # the newest tick (what a live view draws) has it, worked out on the worker; older ones stay lazy
    assert not pending(ticks[-1]) and pending(ticks[0])
    # so are its trajectory and query (a tick that did not search makes them on the first read)
    quiet = [t for t in ticks[:-1] if not t.snapshots["mm"].searched]
    assert quiet
    for name in ("trajectory_positions", "trajectory_rotations"):
        assert not pending(ticks[-1], name) and all(pending(t, name) for t in quiet), name
    assert not pending(ticks[-1], "query")      # (the session's history reads every tick's query cost)
    ghost = ticks[-1].snapshots["mm"].matched_pose_positions
    assert ghost.shape == (len(db.parents), 3) and np.isfinite(ghost).all()


def test_session_steps_records_and_replays(dbf, tmp_path):
    from lmm.data import bvh
    from lmm.data.inputs import load_input_csv

    db, features = dbf
    tuning = Tuning()
    controllers, problems = make_controllers(db, features, tuning, with_lmm=False)
    s = Session(db, features, tuning, controllers, history_seconds=1.0)
    assert s.history.capacity == 60 and controllers["mm"].tuning is tuning
    paths = s.start_recording(tmp_path / "take.bvh", ("mm", "lmm"))   # LMM is not running: MM only
    assert set(paths) == {"mm", "input"} and paths["mm"].name == "take.bvh"
    for i in range(90):
        s.step(InputState(left_y=1.0, camera_azimuth=0.0))
    result = s.stop_recording()
    assert isinstance(result, RecordingResult) and result.frames == 90 and result.seconds == pytest.approx(1.5)
    assert result.message == "recorded 1.50 s (90 frames) to take.bvh, take_input.csv; session take.lmmsession"
    written = result.paths
    assert written == paths
    assert s.history.newest_tick == 90 and len(s.history) == 60
    anim = bvh.load(written["mm"])
    assert anim.n_frames == 90 and anim.n_joints == db.n_bones - 1   # the simulation bone is left out
    pos = anim.global_positions()
    assert np.linalg.norm(pos[-1, 0] - pos[0, 0]) > 50.0        # centimetres: it ran forward
    log = load_input_csv(written["input"])
    assert log.n_rows >= 1 and log.at(0.0).left_y == 1.0 and log.at(1.4).left_y == 1.0
    # replaying the log restarts the characters and feeds the log
    s.replay(log)
    assert s.tick == 0 and len(s.history) == 0
    t = s.step(s.input_for_next_tick(InputState()))
    assert t.extra["input"].left_y == 1.0
    mem = s.memory["mm"]
    assert mem == controllers["mm"].memory_bytes() and mem["pose data (Y)"] == db.pose_bytes()
    assert set(mem) == {"pose data (Y)", "features (X)", "search index"}


def test_recording_never_overwrites_and_never_leaves_empty_files(dbf, tmp_path):
    from lmm.data import bvh

    db, features = dbf
    tuning = Tuning()
    controllers, _ = make_controllers(db, features, tuning, with_lmm=False)
    controllers["mm2"] = make_controllers(db, features, tuning, with_lmm=False)[0]["mm"]   # two characters
    s = Session(db, features, tuning, controllers)
    # nothing recorded: no file ever appears (files appear with their first flushed frames)
    paths = s.start_recording(tmp_path / "take.bvh", ("mm", "mm2"))
    assert [p.name for p in paths.values()] == ["take_mm.bvh", "take_mm2.bvh", "take_input.csv"]
    assert not any(p.exists() for p in paths.values())
    result = s.stop_recording()
    assert result.paths == {} and result.frames == 0 and result.message == "nothing recorded (0 frames): no file written"
    assert list(tmp_path.iterdir()) == []
    # a file of the take exists (only the input CSV): the next free number, one suffix for every file
    (tmp_path / "take_input.csv").write_text("keep me")
    (tmp_path / "take_001_mm2.bvh").write_text("keep me too")
    counts = []
    for n in (5, 7):
        paths = s.start_recording(tmp_path / "take.bvh", ("mm", "mm2"))
        for _ in range(n):
            s.step(InputState(left_y=1.0))
        result = s.stop_recording()
        assert result.paths == paths and result.frames == n
        counts.append({k: p.name for k, p in paths.items()})
        for name in ("mm", "mm2"):
            assert bvh.load(paths[name]).n_frames == n
    assert counts == [{"mm": "take_002_mm.bvh", "mm2": "take_002_mm2.bvh", "input": "take_002_input.csv"},
                      {"mm": "take_003_mm.bvh", "mm2": "take_003_mm2.bvh", "input": "take_003_input.csv"}]
    assert "to take_003_mm.bvh, take_003_mm2.bvh, take_003_input.csv" in result.message
    assert (tmp_path / "take_input.csv").read_text() == "keep me"
    assert (tmp_path / "take_001_mm2.bvh").read_text() == "keep me too"
    assert not (tmp_path / "take_mm.bvh").exists() and not (tmp_path / "take_001_mm.bvh").exists()
    assert s.stop_recording().paths == {}                      # not recording: nothing to stop


def test_a_full_disk_stops_the_studio_recording_and_keeps_valid_files(dbf, tmp_path, monkeypatch):
    import errno
    import os

    from lmm.data import bvh, stream
    from lmm.data.inputs import load_input_csv

    db, features = dbf
    tuning = Tuning()
    controllers, _ = make_controllers(db, features, tuning, with_lmm=False)
    s = Session(db, features, tuning, controllers)
    paths = s.start_recording(tmp_path / "take.bvh", ("mm",))
    for r in s.recording.writers().values():
        r.flush_interval_s = 0.0                              # flush every tick
    for _ in range(20):
        s.step(InputState(left_y=1.0))
    real_write = os.write

    def full(fd, data):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(stream.os, "write", full)
    monkeypatch.setattr(stream.os, "pwrite", lambda fd, data, off: full(fd, data))
    for _ in range(5):
        s.step(InputState(left_y=1.0))                        # the studio keeps ticking
    assert s.recording is None and "No space left" in s.recording_error
    monkeypatch.setattr(stream.os, "write", real_write)
    result = s.stop_recording()
    assert result.frames == 20 and set(result.paths) == {"mm", "input"}
    assert result.message.startswith("recording stopped by a write error: ") and "take.bvh" in result.message
    assert "\n" not in result.message
    assert bvh.load(paths["mm"]).n_frames == 20 and load_input_csv(paths["input"]).n_rows >= 1
    assert s.stop_recording().message == "not recording"


def test_session_fills_projected_frame_and_mm_latents(dbf):
    """The LMM snapshot names the projector's frame, the MM snapshot the latent of its frame once the
    session has attached the compressor's table (computed in the background)."""
    import time

    db, features = dbf
    tuning = Tuning()
    controllers, problems = make_controllers(db, features, tuning)
    if "lmm" not in controllers:
        pytest.skip(f"no LMM networks: {problems}")
    s = Session(db, features, tuning, controllers)
    s.start_latent_table()
    deadline = time.monotonic() + 120
    while s.latent_table_status.startswith("computing") and time.monotonic() < deadline:
        time.sleep(0.05)
    if s.latent_table_status:
        pytest.skip(s.latent_table_status)
    from lmm.latents import database_latents, load_compressor
    table = database_latents(load_compressor(controllers["lmm"].nets.path.with_name("compressor.npz"), db, features),
                             db)
    projected = []
    for _ in range(30):
        t = s.step(InputState(left_y=1.0))
        mm, lmm = t.snapshots["mm"], t.snapshots["lmm"]
        assert np.allclose(mm.matched_latent, table[mm.matched_frame])
        if lmm.searched:
            projected.append(lmm.projected_frame)
            X = controllers["lmm"].features.normalized.astype(np.float64)
            costs = np.sum((X - lmm.projected_features) ** 2, axis=1)
            assert costs[lmm.projected_frame] == pytest.approx(costs.min(), rel=1e-5, abs=1e-6)
    assert projected and s.history.window("lmm", "projected_frame", s.tick, 30)[np.isfinite(
        s.history.window("lmm", "projected_frame", s.tick, 30))].tolist() == projected
    assert s.history.window("mm", "matched_latent", s.tick, 1)[0].tolist() == pytest.approx(
        table[mm.matched_frame].tolist())
    # the networks and the idle set (the shipped weights have the compressor beside them that builds it)
    assert set(s.memory["lmm"]) == {"decompressor", "stepper", "projector", "idle_set"}


def test_reference_clip_loads_and_bad_files_raise(tmp_path):
    from lmm.data.bvh import BVHError

    clip = load_reference_clip(os.path.join(os.path.dirname(__file__), "..", "..", "lmm", "data", "lafan1",
                                            "obstacles3_subject4.bvh.gz"))
    assert clip.positions.shape[1] == 22 and 1.0 < np.ptp(clip.positions[0, :, 1]) < 2.5   # metres
    with pytest.raises(BVHError):
        load_reference_clip(CORPUS / "truncated_frame.bvh")


def test_replaying_a_recorded_input_csv_reproduces_the_motion(dbf, tmp_path):
    from lmm.data.inputs import load_input_csv, open_input

    db, features = dbf
    tuning = Tuning()
    controllers, _ = make_controllers(db, features, tuning, with_lmm=False)
    s = Session(db, features, tuning, controllers)
    s.replay(open_input("builtin:zigzag"))
    written = None
    roots = []
    for i in range(120):
        if i == 0:
            s.start_recording(tmp_path / "take.bvh", ("mm",))
        t = s.step(s.input_for_next_tick(InputState()))
        roots.append(t.snapshots["mm"].pose.global_positions[0].copy())
    written = s.stop_recording().paths
    s.replay(load_input_csv(written["input"]))
    again = [s.step(s.input_for_next_tick(InputState())).snapshots["mm"].pose.global_positions[0] for _ in range(120)]
    assert np.allclose(np.array(roots), np.array(again), atol=1e-5)
    assert np.linalg.norm(roots[-1] - roots[0]) > 1.0
