"""Motion quality (lmm.quality): the product's figures against an independent computation on a made-up
motion with one known pop and one known knee snap; the stream against the whole-clip kernels; the
database's own figures; stops and settling."""

import math

import numpy as np
import pytest

from lmm.metrics import DurationStats
from lmm.quality import (QualityJoints, MotionQuality, clip_quality, knee_angles_deg, reference_quality, resample)

NAMES = ["Simulation", "Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToe",
         "RightUpLeg", "RightLeg", "RightFoot", "RightToe"]
PARENTS = [-1, 0, 1, 2, 3, 4, 1, 6, 7, 8]
REF = {"max_acceleration": 60.0, "max_knee_acceleration": 20000.0, "min_knee_angle": 5.0,
       "acceleration_p99_slow": 5.0, "jerk_p99": 500.0}


def _walk(seconds=4.0, fps=60.0, speed=1.0):
    """World positions (F, 10, 3): the root and hips moving at ``speed`` along x, each leg's knee bending
    smoothly between 10 and 40 degrees (legs 0.4 m + 0.4 m in the x-y plane), toes 5 cm ahead of the ankles."""
    t = np.arange(int(seconds * fps)) / fps
    F = len(t)
    p = np.zeros((F, 10, 3))
    p[:, 0, 0] = speed * t
    p[:, 1] = p[:, 0] + [0, 0.9, 0]
    for side, (hip, knee, ankle, toe), phase in ((0, (2, 3, 4, 5), 0.0), (1, (6, 7, 8, 9), math.pi)):
        z = 0.1 if side else -0.1
        p[:, hip] = p[:, 1] + [0, 0, z]
        bend = np.radians(25 + 15 * np.sin(2 * math.pi * t + phase))
        p[:, knee] = p[:, hip] + np.stack([np.zeros(F), -0.4 * np.ones(F), np.zeros(F)], -1)
        p[:, ankle] = p[:, knee] + 0.4 * np.stack([np.sin(bend), -np.cos(bend), np.zeros(F)], -1)
        p[:, toe] = p[:, ankle] + [0.05, -0.05, 0]
    return p


def _independent(p60, ref):
    """The definitions written out sample by sample in plain Python (1/30 s: every other 60 fps frame)."""
    p = p60[::2]
    h = 1 / 30
    legs = [(2, 3, 4), (6, 7, 8)]

    def knee(q, leg):
        a, b, c = (np.array(q[j]) for j in leg)
        u, v = b - a, c - b
        return math.degrees(math.acos(max(-1.0, min(1.0, float(u @ v) / (np.linalg.norm(u) * np.linalg.norm(v))))))

    pops = snaps = straight = 0
    for i in range(len(p)):
        if min(knee(p[i], leg) for leg in legs) < ref["min_knee_angle"]:
            straight += 1
        if 1 <= i < len(p) - 1:
            a = max(float(np.linalg.norm(p[i + 1, j] - 2 * p[i, j] + p[i - 1, j])) / h ** 2 for j in range(10))
            pops += a > ref["max_acceleration"]
            ka = max(abs(knee(p[i + 1], leg) - 2 * knee(p[i], leg) + knee(p[i - 1], leg)) / h ** 2 for leg in legs)
            snaps += ka > ref["max_knee_acceleration"]
    minutes = (len(p) - 1) * h / 60
    return pops / minutes, snaps / minutes, straight / len(p)


def test_one_pop_and_one_knee_snap_agree_with_an_independent_computation():
    joints = QualityJoints.of(NAMES, PARENTS)
    smooth = _walk()
    clean = clip_quality(smooth, 60.0, joints, REF, DurationStats)
    assert clean["quality_pops_per_min"] == 0 and clean["quality_knee_snaps_per_min"] == 0
    assert clean["quality_straight_knee_fraction"] == 0
    p = smooth.copy()
    p[60, 9] += [0.0, 0.08, 0.0]            # the right toe jumps 8 cm up for one 30 fps sample: a pop
    p[120, 4] = p[120, 3] + (p[120, 3] - p[120, 2])   # the left leg straight for one sample: a knee snap
    p[120, 5] = p[120, 4] + [0.05, -0.05, 0]
    got = clip_quality(p, 60.0, joints, REF, DurationStats)
    pops, snaps, straight = _independent(p, REF)
    assert got["quality_pops_per_min"] == pytest.approx(pops)
    assert got["quality_knee_snaps_per_min"] == pytest.approx(snaps)
    assert got["quality_straight_knee_fraction"] == pytest.approx(straight)
    minutes = (len(p[::2]) - 1) / 30 / 60
    assert round(snaps * minutes) >= 1 and round(pops * minutes) >= 2   # the snap pops the foot too
    assert got["quality_worst_pop_s"] in (pytest.approx(1.0, abs=0.04), pytest.approx(2.0, abs=0.04))
    assert got["quality_worst_knee_snap_s"] == pytest.approx(2.0, abs=0.04)


def test_figures_do_not_depend_on_the_frame_rate():
    joints = QualityJoints.of(NAMES, PARENTS)
    p = _walk()
    p[120, 9] += [0.0, 0.08, 0.0]
    a = clip_quality(p, 60.0, joints, REF, DurationStats)
    b = clip_quality(p[::2], 30.0, joints, REF, DurationStats)
    for k in ("quality_pops_per_min", "quality_knee_snaps_per_min", "quality_straight_knee_fraction",
              "quality_jerk_p99_ratio"):
        assert a[k] == pytest.approx(b[k]), k
    # an odd rate is interpolated onto the same 1/30 s steps
    assert len(resample(p[:121], 60.0)) == 61 and len(resample(np.zeros((49, 2, 3)), 48.0)) == 31


def test_knee_angle_is_zero_for_a_straight_leg():
    p = np.zeros((1, 10, 3))
    p[0, 3, 1], p[0, 4, 1] = -0.4, -0.8
    p[0, 7, 1], p[0, 8] = -0.4, [0.4, -0.4, 0]
    k = knee_angles_deg(p, QualityJoints.of(NAMES, PARENTS).legs)
    assert k[0, 0] == pytest.approx(0.0, abs=1e-6) and k[0, 1] == pytest.approx(90.0)


def test_a_stop_settles_and_a_raised_toe_is_seen():
    joints = QualityJoints.of(NAMES, PARENTS)
    run = _walk(seconds=2.0, speed=2.0)
    still = np.repeat(run[-1:], 240, axis=0)          # then 4 s standing still
    p = np.concatenate([run, still])
    q = MotionQuality(joints, REF, DurationStats)
    for i, x in enumerate(p):
        q.add(i / 60, x)
    r = q.result()
    assert r["quality_stops"] == 1 and r["quality_stops_unsettled"] == 0
    assert r["quality_settle_s_median"] < 0.1
    assert r["quality_stops_raised_toe"] == r["quality_stops_raised_knee"] == 0

    def stand_with(leg):   # the left leg (hip, knee, ankle, toe: joints 2-5) posed for 20 frames of the stand
        raised = p.copy()
        hip = raised[150:170, 2]
        for j, offset in zip((3, 4, 5), leg):
            raised[150:170, j] = hip + offset
        q = MotionQuality(joints, REF, DurationStats)
        for i, x in enumerate(raised):
            q.add(i / 60, x)
        return q.result()

    # the knee lifted to level, the shin hanging: the toe 45 cm up in front, a raised knee
    knee_up = stand_with([(0.4, 0.0, -0.1), (0.4, -0.4, -0.1), (0.45, -0.45, -0.1)])
    assert knee_up["quality_stops_raised_toe"] == 1 and knee_up["quality_stops_raised_knee"] == 1
    assert knee_up["quality_stop_toe_max_m"] == pytest.approx(0.9 - 0.45, abs=0.01)
    # the thigh hanging 10 degrees back, the shin folded up behind it: the toe as high, a heel kicked up in a
    # stride, not a raised knee
    back = 0.4 * math.sin(math.radians(10)), -0.4 * math.cos(math.radians(10))
    heel_up = stand_with([(-back[0], back[1], -0.1), (-back[0] - 0.4, back[1], -0.1),
                          (-back[0] - 0.45, back[1] + 0.05, -0.1)])
    assert heel_up["quality_stops_raised_toe"] == 1 and heel_up["quality_stops_raised_knee"] == 0


def test_thigh_raise_deg():
    from lmm.quality import thigh_raise_deg

    assert thigh_raise_deg((0, 1, 0), (0, 0.6, 0)) == pytest.approx(0.0)
    assert thigh_raise_deg((0, 1, 0), (0.4, 1, 0)) == pytest.approx(90.0)
    assert thigh_raise_deg((0, 1, 0), (-0.3, 0.7, 0)) == pytest.approx(45.0)


def test_the_databases_own_figures(db):
    ref = reference_quality(db)
    assert 50 < ref["max_acceleration"] < 1000 and 0 < ref["min_knee_angle"] < 20
    assert 0 < ref["acceleration_p99_slow"] < ref["max_acceleration"] and ref["jerk_p99"] > 0
    # measured by the stream, the database's longest range has no pop and no knee snap beyond its own maxima
    r = int(np.argmax(db.range_stops - db.range_starts))
    _, pos = db.global_transforms(slice(int(db.range_starts[r]), int(db.range_stops[r])))
    got = clip_quality(pos, db.fps, QualityJoints.of_database(db), ref, DurationStats)
    assert got["quality_pops_per_min"] == 0 and got["quality_knee_snaps_per_min"] == 0
    assert got["quality_straight_knee_fraction"] == 0


def test_response_time_to_a_step_of_the_desired_velocity():
    """The root follows a step of the desired velocity from 0 to 3 m/s as 1 - exp(-t / tau): 90 % of it is
    reached at tau ln 10 (within a 1/30 s sample)."""
    joints = QualityJoints.of(NAMES, PARENTS)
    tau, fps = 0.4, 60.0
    q = MotionQuality(joints, REF, DurationStats)
    x = 0.0
    for i in range(int(6 * fps)):
        t = i / fps
        on = t >= 1.0
        v = 3.0 * (1.0 - math.exp(-(t - 1.0) / tau)) if on else 0.0
        x += v / fps
        p = _walk(seconds=1 / fps, speed=0.0)[0]
        p[:, 0] += x
        q.add(t, p, (3.0, 0.0, 0.0) if on else (0.0, 0.0, 0.0))
    r = q.result()
    assert r["quality_steps"] == 1
    assert r["quality_response_s_median"] == pytest.approx(tau * math.log(10.0), abs=1.5 / 30)


def test_the_steps_input_stands_runs_reverses_turns_and_stops():
    from lmm.data.inputs import builtin
    log = builtin("steps", 32.0)
    speeds = [math.hypot(log(t).left_x, log(t).left_y) for t in (1.0, 4.0, 7.0, 10.0, 14.0, 17.0, 20.0)]
    assert speeds == pytest.approx([0, 1, 1, 1, 0, 0, 1])
    fwd, back, side = log(4.0), log(7.0), log(10.0)
    assert fwd.left_y == pytest.approx(1) and back.left_y == pytest.approx(-1) and abs(side.left_x) == pytest.approx(1)


def test_played_frames_accelerations_are_the_databases_own(db):
    """:class:`PlayedAccelerations` at a frame: the second differences of the database's world positions
    1/30 s either side of it, written out here from the whole range; None where that step leaves the range
    or for no frame."""
    from lmm.quality import PlayedAccelerations

    played = PlayedAccelerations(db)
    r = int(np.argmax(db.range_stops - db.range_starts))
    lo, hi = int(db.range_starts[r]), int(db.range_stops[r])
    _, pos = db.global_transforms(slice(lo, hi))
    k = int(round(db.fps / 30))
    assert k * 30 == db.fps      # the shipped data is 60 fps: whole frames either side
    for f in (lo + k, (lo + hi) // 2, hi - 1 - k):
        i = f - lo
        want = np.linalg.norm(pos[i + k] - 2 * pos[i] + pos[i - k], axis=-1) * 30.0 ** 2
        np.testing.assert_allclose(played(f), want, rtol=1e-9, atol=1e-9)
    assert played(lo + k - 1) is None and played(hi - k) is None and played(-1) is None


def test_a_run_that_plays_the_database_has_its_played_figure(db):
    """Fed a range of the database as it is, with the frames it plays, the low-speed acceleration p99 and
    the played frames' p99 are the same values: the played frame of each sample lines up with it. Frames
    a second off give another figure."""
    from lmm.quality import PlayedAccelerations

    joints, ref, played = QualityJoints.of_database(db), reference_quality(db), PlayedAccelerations(db)
    best = None
    for r in range(len(db.range_starts)):
        lo, hi = int(db.range_starts[r]), int(db.range_stops[r])
        if hi - lo < 600 or db.range_mirrored[r]:
            continue
        _, pos = db.global_transforms(slice(lo, hi))
        speed = np.hypot(*(pos[2:, 0, [0, 2]] - pos[:-2, 0, [0, 2]]).T) * 30.0
        slow = float(np.mean(speed < 0.5))
        if 0.2 < slow < 0.8 and (best is None or hi - lo > best[1] - best[0]):
            best = (lo, hi, pos)
    assert best is not None, "no range that both stands and moves"
    lo, hi, pos = best
    frames = np.arange(lo, hi)
    got = clip_quality(pos, db.fps, joints, ref, DurationStats, frames=frames, played=played)
    assert math.isfinite(got["quality_acceleration_p99_slow_ratio"])
    assert got["quality_acceleration_p99_slow_played_ratio"] == pytest.approx(
        got["quality_acceleration_p99_slow_ratio"], rel=1e-12)
    off = clip_quality(pos, db.fps, joints, ref, DurationStats, frames=np.clip(frames + 60, lo, hi - 1), played=played)
    assert off["quality_acceleration_p99_slow_played_ratio"] != pytest.approx(
        got["quality_acceleration_p99_slow_ratio"], rel=1e-3)
    # without frames (a recording): no played figure
    none = clip_quality(pos, db.fps, joints, ref, DurationStats)
    assert math.isnan(none["quality_acceleration_p99_slow_played_ratio"])


def test_runs_report_the_played_frames_figure(db):
    """``run --metrics-json``'s metrics (:class:`lmm.metrics.MotionMetrics`) carry the played frames' p99
    for both controllers' kind of run: a motion matching run that stands, starts and stops."""
    from lmm.data.inputs import open_input
    from lmm.factory import make_controller
    from lmm.features import build_features
    from lmm.runner import run_headless

    c = make_controller("mm", db, build_features(db), None, None, debug_comparison=False)
    m = run_headless(c, open_input("builtin:steps", 16.0), 16.0)
    assert 0.0 < m["quality_acceleration_p99_slow_played_ratio"] < 10.0
    assert m["quality_acceleration_p99_slow_ratio"] > 0.0


def test_played_frames_between_whole_frames_are_interpolated():
    """At a rate that is not a multiple of 30 fps the frames 1/30 s either side fall between whole frames
    and are linear between the two around each: on x = c n^2 (n the frame) that adds c w (1 - w) to each
    side, so the second difference is (2 c r^2 + 2 c w (1 - w)) / h^2 with r = fps / 30 frames, w its
    fraction."""
    from types import SimpleNamespace

    from lmm.quality import PlayedAccelerations

    c, fps = 0.01, 50.0

    def global_transforms(frames):
        n = np.asarray(frames, np.float64)
        pos = np.zeros((len(n), 2, 3))
        pos[:, 1, 0] = c * n ** 2
        return None, pos

    db = SimpleNamespace(fps=fps, n_frames=100, range_starts=np.array([0]), range_stops=np.array([100]),
                         range_index=lambda f: 0, global_transforms=global_transforms)
    played = PlayedAccelerations(db)
    r = fps / 30
    w = r - math.floor(r)
    got = played(50)
    assert got[0] == 0.0
    assert got[1] == pytest.approx((2 * c * r * r + 2 * c * w * (1 - w)) * 30.0 ** 2, rel=1e-9)
    assert played(1) is None and played(98) is None
