"""Following a reference take (lmm.follow): the aligned take, the aligned frame search and the pose error,
and the studio session that replays the take's input and keeps the error per tick (no display)."""
import math

import numpy as np
import pytest

from lmm import DEFAULT_MANIFEST
from lmm.compare import motion_from_arrays
from lmm.controller import InputState
from lmm.data import bvh
from lmm.data.manifest import load_manifest
from lmm.errors import InputError
from lmm.follow import FollowError, FrameTracker, follow_take, pose_rotations

TAKE = "lmm/data/lafan1/obstacles3_subject3.bvh.gz"
RANGE = (3526, 3781)            # a held-out walk (lmm/data/heldout.json), 8.5 s at 30 fps


@pytest.fixture(scope="module")
def manifest():
    return load_manifest(DEFAULT_MANIFEST)


@pytest.fixture(scope="module")
def anim():
    from pathlib import Path

    return bvh.load(Path(__file__).resolve().parents[2] / TAKE)


@pytest.fixture(scope="module")
def take(anim, manifest):
    return follow_take(anim, manifest, ["Simulation", *anim.names], path=TAKE, frames=RANGE)


def test_the_take_is_aligned_to_start_at_the_origin_facing_z(take, anim, manifest):
    d = take.derived
    assert take.n_frames == RANGE[1] - RANGE[0] and abs(take.fps - 30.0) < 0.01
    assert len(d.inputs) == int(math.floor(take.duration_s * 60 + 1e-9))
    # the root path starts at the origin facing +Z (one tick in: within a few centimetres and degrees)
    assert np.linalg.norm(d.reference_positions[0][[0, 2]]) < 0.05 and abs(d.reference_yaw[0]) < 0.05
    # the drawn joints are turned and moved with it: the hips stay over the root path all along ...
    hips = take.positions[:, anim.names.index(manifest.bones["hips"])]
    ticks = np.minimum(np.round(np.arange(take.n_frames) / take.fps * 60).astype(int), len(d.inputs))
    gap = np.linalg.norm((hips - np.array([take.root_at(max(t, 1)) for t in ticks]))[:, [0, 2]], axis=1)
    assert gap.max() < 0.3, gap.max()
    # ... which walks forward (+Z) at the start, whatever way the take faced in the file
    assert hips[30, 2] - hips[0, 2] > 0.5 and abs(hips[30, 0] - hips[0, 0]) < 0.3


def test_the_pose_rotations_are_compare_py_s_definition(anim, manifest):
    names = ["Simulation", *anim.names]
    g_rot, g_pos = anim.global_transforms()
    f = 3600
    local = np.concatenate([[[1.0, 0, 0, 0]], anim.local_rotations()[f]])
    glob = np.concatenate([[[1.0, 0, 0, 0]], g_rot[f]])
    pos = np.concatenate([[[0.0, 0, 0]], g_pos[f]])
    ours = pose_rotations(local, glob, names, manifest.hips_forward_axis)
    theirs = motion_from_arrays("x", names, local[None], glob[None], pos[None], 30.0, manifest.hips_forward_axis)
    assert ours.shape == (len(anim.names), 4)
    np.testing.assert_allclose(ours, theirs.rotations[0], atol=1e-12)


def test_the_tracker_finds_the_take_s_own_frames(take):
    tr = FrameTracker(take)
    assert tr.window == 9                                     # 0.3 s at 30 fps
    # the take's own pose at each frame's time: that frame, error 0
    for f in (0, 10, 40, 100):
        frame, err = tr.track(f / take.fps, take.rotations[f])
        assert frame == f and err < 1e-9
    # a pose 5 frames late is found within the search window (error 0), ...
    frame, err = tr.track(120 / take.fps, take.rotations[125])
    assert frame == 125 and err < 1e-9
    # ... one 20 frames late is not (0.67 s: outside), the error is then the best one inside
    frame, err = tr.track(140 / take.fps, take.rotations[165])
    assert 131 <= frame <= 149 and err > 0.0
    # monotone: a pose from the past does not move the frame back
    prev = frame
    frame, err = tr.track(141 / take.fps, take.rotations[135])
    assert frame >= prev and err > 0.0
    # past the end (and its window): the last frame, no error
    frame, err = tr.track(take.duration_s + 1.0, take.rotations[-1])
    assert frame == take.n_frames - 1 and math.isnan(err)
    tr.reset()
    frame, err = tr.track(0.0, take.rotations[0])
    assert frame == 0 and err < 1e-9


def test_the_error_is_the_mean_joint_angle(take):
    # every joint turned by 0.2 rad about some axis: the error is 0.2 (the search finds no better frame,
    # for a pose turned off every frame of the take)
    axis = np.array([0.3, 0.9, -0.3]) / np.linalg.norm([0.3, 0.9, -0.3])
    from lmm import quat

    turn = quat.from_axis_angle(axis, np.array(0.2))
    q = quat.mul(take.rotations[50], np.broadcast_to(turn, take.rotations[50].shape))
    frame, err = FrameTracker(take, search_s=0.0).track(50 / take.fps, q)
    assert frame == 50 and abs(err - 0.2) < 1e-9


def test_a_take_without_the_needed_bones_cannot_be_followed(anim, manifest):
    with pytest.raises(FollowError) as e:
        follow_take(anim, manifest, ["Simulation", *anim.names, "LeftPinky"], path="walk.bvh", frames=RANGE)
    msg = str(e.value)
    assert "\n" not in msg and "walk.bvh" in msg and "LeftPinky" in msg
    renamed = bvh.Animation.from_local([("Pelvis" if n == "Hips" else n) for n in anim.names], anim.parents,
                                       anim.offsets, anim.local_rotations()[:60], anim.local_positions()[:60],
                                       anim.frame_time)
    with pytest.raises(InputError) as e:
        follow_take(renamed, manifest, ["Simulation", *renamed.names], path="pelvis.bvh")
    assert "\n" not in str(e.value) and "pelvis.bvh" in str(e.value) and "Hips" in str(e.value)


def test_history_keeps_tick_series_and_blanks_the_ticks_without(take):
    from app.history import History, Tick

    h = History(10)
    h.append(Tick(1, 1 / 60, {}, series={("mm", "reference_error"): 0.25}))
    h.append(Tick(2, 2 / 60, {}))
    h.append(Tick(3, 3 / 60, {}, series={("mm", "reference_error"): 0.5}))
    for t in range(4, 14):                                  # wraps: slot 1 and 3 are reused
        h.append(Tick(t, t / 60, {}))
    h.append(Tick(14, 14 / 60, {}, series={("mm", "reference_error"): 0.75}))
    y = h.window("mm", "reference_error", 14, 10)
    assert np.isnan(y[:-1]).all() and y[-1] == 0.75


def test_the_session_follows_a_take(db, features, take):
    from app.session import Session
    from lmm.factory import make_controllers
    from lmm.tuning import Tuning

    tuning = Tuning()
    controllers, _ = make_controllers(db, features, tuning, with_lmm=False)
    s = Session(db, features, tuning, controllers)
    for _ in range(5):                                      # some live ticks first: follow resets them
        s.step(s.input_for_next_tick(InputState(0.0, 1.0)))
    s.follow(take)
    assert s.tick == 0 and s.following is take
    errors, gaps = [], []
    for _ in range(240):
        tick = s.step(s.input_for_next_tick(None))
        errors.append(tick.series[("mm", "reference_error")])
        root = tick.snapshots["mm"].pose.global_positions[0]
        gaps.append(np.linalg.norm((root - take.root_at(tick.tick))[[0, 2]]))
    errors = np.array(errors)
    assert np.isfinite(errors).all() and 0.05 < errors.mean() < 1.0, errors.mean()
    assert np.mean(gaps) < 0.15 and max(gaps) < 0.4, (np.mean(gaps), max(gaps))
    frames = s.history.window("mm", "reference_frame", s.history.newest_tick, 240)
    assert (np.diff(frames) >= 0).all()                     # monotone
    assert (np.abs(frames - np.arange(1, 241) / 60 * take.fps) <= 9.5).all()   # within 0.3 s of the time
    s.stop_replay()
    assert s.following is None
    tick = s.step(InputState())
    assert [k for k in tick.series if k[1] != "quality_flag"] == []   # no follow series (the quality flag stays)
