"""The per-tick motion of one character in plain floats (input -> desired motion -> simulation springs ->
predicted trajectory -> query) against direct definitions in numpy written here (the closed-form
springs and quaternion maths of lmm.springs and lmm.quat), bit for bit (recordings depend on it), and
the feature weights are re-applied when, and only when, they change."""
import numpy as np
import pytest

from lmm import quat
from lmm.controller import InputState
from lmm.features import build_query, build_query_from_columns, trajectory_query_columns
from lmm.mm import MotionMatchingController
from lmm.springs import _spring_damper_exact_quat_arrays, halflife_to_damping, spring_character_update, spring_rotation_update
from lmm.trajectory import (desired_rotation, desired_velocity, simulation_update, stick_world, trajectory_in_root_space,
                            trajectory_predict, yaw_rotation)
from lmm.tuning import Tuning

UP, FORWARD = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])


# -- the definitions, in numpy -------------------------------------------------------------------------

def np_yaw_rotation(angle):
    return quat.from_axis_angle(UP, np.asarray(angle, dtype=np.float64))


def np_stick_world(x, y, deadzone, camera_azimuth):
    """Radial deadzone (zero inside, rescaled outside so full deflection stays 1), then the camera's turn."""
    s = np.array([x, y], dtype=np.float64)
    mag = float(np.hypot(s[0], s[1]))
    s = np.zeros(2) if mag <= deadzone or mag <= 0.0 else s * (min((mag - deadzone) / max(1.0 - deadzone, 1e-6), 1.0) / mag)
    return quat.mul_vec(np_yaw_rotation(camera_azimuth), np.array([-s[0], 0.0, s[1]]))


def np_desired_velocity(stick, simulation_rotation, walk, tuning):
    t = tuning
    fwd, side, back = ((t.walk_forward_speed_m_s, t.walk_sideways_speed_m_s, t.walk_backwards_speed_m_s) if walk
                       else (t.run_forward_speed_m_s, t.run_sideways_speed_m_s, t.run_backwards_speed_m_s))
    local = quat.inv_mul_vec(simulation_rotation, stick)
    return quat.mul_vec(simulation_rotation, np.array([local[0] * side, 0.0, local[2] * (fwd if local[2] > 0.0 else back)]))


def np_desired_rotation(stick, right_stick, velocity, current_rotation, strafe, camera_azimuth):
    def facing(d):
        return np_yaw_rotation(np.arctan2(d[..., 0], d[..., 2]))
    if strafe:
        return facing(right_stick) if np.linalg.norm(right_stick) > 1e-5 else np_yaw_rotation(camera_azimuth)
    return facing(velocity) if np.linalg.norm(velocity) > 1e-5 else np.array(current_rotation, dtype=np.float64)


def np_spring_character(x, v, a, v_goal, halflife, dt):
    """v(t) = v_goal + e^{-y t} (j0 + j1 t), j0 = v0 - v_goal, j1 = a0 + j0 y; x(t) its exact integral; ``dt``
    may be an array of horizons (a horizon axis before the vector axis)."""
    y = halflife_to_damping(halflife) / 2.0
    dt = np.asarray(dt, dtype=np.float64)
    if dt.ndim:
        dt = dt[..., None]
    j0 = v - v_goal
    j1 = a + j0 * y
    e = np.exp(-y * dt)
    x_new = e * ((-j1) / (y * y) + (-j0 - j1 * dt) / y) + j1 / (y * y) + j0 / y + v_goal * dt + x
    return x_new, e * (j0 + j1 * dt) + v_goal, e * (a - j1 * y * dt)


def np_simulation_update(x, v, a, q, w, goal_v, goal_q, vh, rh, dt):
    x, v, a = np_spring_character(x, v, a, goal_v, vh, dt)
    q, w = _spring_damper_exact_quat_arrays(q, w, goal_q, rh, dt)
    return x, v, a, quat.normalize(q), w


def np_trajectory_predict(x, v, a, q, w, goal_v, goal_q, vh, rh, times):
    pos, _, _ = np_spring_character(x, v, a, goal_v, vh, times)
    rot, _ = _spring_damper_exact_quat_arrays(q, w, goal_q, rh, times)
    return pos, quat.normalize(rot)


def np_trajectory_in_root_space(positions, rotations, root_position, root_rotation):
    return (quat.inv_mul_vec(root_rotation, positions - root_position),
            quat.inv_mul_vec(root_rotation, quat.mul_vec(rotations, FORWARD)))


TIMES = (20 / 60, 40 / 60, 60 / 60)


def _same(a, b):
    """Equal values and equal signs of zero (a -0.0 can become a different angle downstream)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=True) and np.array_equal(np.signbit(a), np.signbit(b))


def _t(a):
    return tuple(np.asarray(a, np.float64).tolist())


def _quat(rng):
    q = quat.normalize(rng.normal(size=4))
    return q if rng.random() < 0.8 else -q


def _states(rng, n):
    for i in range(n):
        scale = 0.0 if i % 9 == 0 else float(rng.uniform(0.01, 5.0))
        yield (rng.normal(size=3) * 10, rng.normal(size=3) * scale, rng.normal(size=3) * scale, _quat(rng),
               rng.normal(size=3) * scale)


def test_the_comparison_sees_the_sign_of_zero():
    assert not _same(yaw_rotation(-0.0), yaw_rotation(0.0))
    assert _same(yaw_rotation(-0.0), np_yaw_rotation(-0.0))


def test_sticks_and_desired_motion():
    rng = np.random.default_rng(3)
    tun = Tuning()
    sticks = [(0.0, 0.0), (-0.0, 0.0), (0.05, 0.0), (1.0, 0.0), (0.0, -1.0), (0.9, 0.9)]
    sticks += [tuple(rng.uniform(-1, 1, 2).tolist()) for _ in range(300)]
    rotations = [np.array([1.0, 0, 0, 0])] + [_quat(rng) for _ in range(20)]
    for i, (x, y) in enumerate(sticks):
        az = [0.0, -0.0, float(rng.uniform(-7, 7))][i % 3]
        dz = [0.0, 0.1, 0.25][i % 3]
        want = np_stick_world(x, y, dz, az)
        got = stick_world(x, y, dz, az)
        assert _same(got, want), (x, y, dz, az)
        right = np_stick_world(y, -x, dz, az)
        sim_rot, current = rotations[i % len(rotations)], rotations[(i + 1) % len(rotations)]
        for walk in (False, True):
            vel = np_desired_velocity(want, sim_rot, walk, tun)
            vel_t = desired_velocity(got, _t(sim_rot), walk, tun)
            assert _same(vel_t, vel)
            for strafe in (False, True):
                for r in (right, np.zeros(3)):
                    assert _same(desired_rotation(got, _t(r), vel_t, _t(current), strafe, az),
                                 np_desired_rotation(want, r, vel, current, strafe, az))


def test_springs_one_state():
    rng = np.random.default_rng(4)
    for i, (x, v, a, q, w) in enumerate(_states(rng, 300)):
        goal_v = rng.normal(size=3) * 3
        goal_q = q.copy() if i % 7 == 0 else _quat(rng)
        halflife = [0.0, 0.1, float(rng.uniform(0, 1))][i % 3]
        for dts in ((1 / 60,), (float(rng.uniform(0, 3)),), TIMES):
            dt = np.array(dts) if len(dts) > 1 else dts[0]
            got = spring_character_update(_t(x), _t(v), _t(a), _t(goal_v), halflife, dts)
            for k, want in enumerate(np_spring_character(x, v, a, goal_v, halflife, dt)):
                assert _same([g[k] for g in got], np.reshape(want, (len(dts), 3)))
            assert _same(spring_character_update(_t(x), _t(v), _t(a), _t(goal_v), halflife, dts, positions_only=True),
                         [g[0] for g in got])
            got = spring_rotation_update(_t(q), _t(w), _t(goal_q), halflife, dts)
            want_q, want_w = _spring_damper_exact_quat_arrays(q, w, goal_q, halflife, dt)
            assert _same([g[0] for g in got], np.reshape(want_q, (len(dts), 4)))
            assert _same([g[1] for g in got], np.reshape(want_w, (len(dts), 3)))
            normed = spring_rotation_update(_t(q), _t(w), _t(goal_q), halflife, dts, normalize=True)
            assert _same([g[0] for g in normed], quat.normalize(np.reshape(want_q, (len(dts), 4))))


def test_simulation_trajectory_and_root_space():
    rng = np.random.default_rng(5)
    for i, (x, v, a, q, w) in enumerate(_states(rng, 200)):
        goal_v, goal_q = rng.normal(size=3) * 3, _quat(rng)
        vh, rh = float(rng.uniform(0, 0.5)), float(rng.uniform(0, 0.5))
        want = np_simulation_update(x, v, a, q, w, goal_v, goal_q, vh, rh, 1 / 60)
        got = simulation_update(_t(x), _t(v), _t(a), _t(q), _t(w), _t(goal_v), _t(goal_q), vh, rh, 1 / 60)
        for g, w_, name in zip(got, want, ("position", "velocity", "acceleration", "rotation", "angular_velocity")):
            assert _same(g, w_), name
        want_pos, want_rot = np_trajectory_predict(*want, goal_v, goal_q, vh, rh, np.array(TIMES))
        got_pos, got_rot = trajectory_predict(*got, _t(goal_v), _t(goal_q), vh, rh, TIMES)
        assert _same(got_pos, want_pos) and _same(got_rot, want_rot)
        root_pos, root_rot = rng.normal(size=3) * 10, _quat(rng)
        want_lp, want_ld = np_trajectory_in_root_space(want_pos, want_rot, root_pos, root_rot)
        got_lp, got_ld = trajectory_in_root_space(got_pos, got_rot, _t(root_pos), _t(root_rot))
        assert _same(got_lp, want_lp) and _same(got_ld, want_ld)


def test_query_and_normalize(features):
    rng = np.random.default_rng(6)
    offsets = sorted({o for ch in features.layout if ch.kind.startswith("trajectory") for o in ch.offsets})
    index = {o: i for i, o in enumerate(offsets)}
    columns = trajectory_query_columns(features, index)
    for _ in range(50):
        current = features.raw[int(rng.integers(len(features.raw)))]
        pos, dirs = rng.normal(size=(len(offsets), 3)) * 5, rng.normal(size=(len(offsets), 3))
        want = build_query(features, current, lambda o: (pos[index[o]], dirs[index[o]]))
        got = build_query_from_columns(current, columns, [_t(p) for p in pos], [_t(d) for d in dirs])
        assert got.dtype == np.float32 and _same(got, want)
        assert _same(features.normalize(got), ((want - features.mean) * features.inv_scale).astype(np.float32))
        raw64 = want.astype(np.float64) + rng.normal(size=want.shape) * 1e-3
        norm64 = features.normalize(raw64)
        assert norm64.dtype == np.float32 and _same(norm64, ((raw64 - features.mean) * features.inv_scale).astype(np.float32))


def test_feature_weights_follow_the_tuning(db, features):
    c = MotionMatchingController(db, features)
    inp = InputState(left_y=1.0)
    for _ in range(3):
        c.step(inp, 1 / 60)
    name = c.features.layout[0].name
    i = 0
    before = c.features.normalized
    c.tuning.feature_weights[name] = 2.5  # a slider writes the dict in place
    c.step(inp, 1 / 60)
    assert c.features.weights[i] == np.float32(2.5) and c.features.normalized is not before
    same = c.features.normalized
    c.step(inp, 1 / 60)
    assert c.features.normalized is same  # unchanged weights: no rebuild
    c.features.set_weights({name: 0.5})  # someone else changed the features: the tuning wins again
    c.step(inp, 1 / 60)
    assert c.features.weights[i] == np.float32(2.5)
    c.tuning.feature_weights = dict(c.tuning.feature_weights, **{name: 1.25})  # a new dict (a preset)
    c.step(inp, 1 / 60)
    assert c.features.weights[i] == np.float32(1.25)
    c.tuning.feature_weights[name] = -1.0
    with pytest.raises(ValueError):
        c.step(inp, 1 / 60)


def test_remembered_stick_and_simulation_floats():
    """The remembering stick answers what the plain function answers, signs of zero included; the float
    simulation state reads as the arrays it holds."""
    from lmm.trajectory import SimulationState, StickWorld
    stick = StickWorld()
    rng = np.random.default_rng(7)
    calls = [(0.0, 0.0, 0.1, 0.0), (0.0, 0.0, 0.1, -0.0), (-0.0, 0.5, 0.1, 0.0), (0.0, 0.5, 0.1, 0.0),
             (0.0, 0.5, 0.1, 0.0), (0.3, 0.4, 0.1, 1.0), (0.3, 0.4, 0.1, 1.0), (0.3, 0.4, 0.2, 1.0)]
    calls += [tuple(rng.uniform(-1, 1, 2).tolist()) + (0.1, 0.5) for _ in range(20) for _ in range(2)]
    for args in calls:
        assert _same(stick(*args), stick_world(*args)), args
    state = tuple(tuple(rng.normal(size=n).tolist()) for n in (3, 3, 3, 4, 3))
    sim = SimulationState(state)
    names = ("position", "velocity", "acceleration", "rotation", "angular_velocity")
    for name, want in zip(names, state):
        assert _same(getattr(sim, name), want) and _same(getattr(sim.copy(), name), want)


def test_trajectory_columns_as_a_slice(features):
    offsets = sorted({o for ch in features.layout if ch.kind.startswith("trajectory") for o in ch.offsets})
    dims, picks = trajectory_query_columns(features, {o: i for i, o in enumerate(offsets)})
    kinds = ("trajectory_position", "trajectory_direction")
    want = [d for ch, s in zip(features.layout, features.slices) if ch.kind in kinds for d in range(s.start, s.stop)]
    assert list(range(len(features.mean)))[dims] == want and len(picks) == len(want)


def test_rotation_distance_is_the_numpy_definition_bit_for_bit():
    """The sharp-input test's rotation rate: the angle between two rotations in plain floats is the numpy
    definition's, bit for bit (negative w, tiny and half-turn differences)."""

    rng = np.random.default_rng(8)
    for i in range(3000):
        a = rng.normal(size=4)
        a /= np.linalg.norm(a)
        kind = i % 4
        if kind == 0:
            b = -a                                            # the same rotation, other sign
        elif kind == 1:
            b = a + rng.normal(size=4) * 1e-10                # a tiny difference (the small branch)
        else:
            b = rng.normal(size=4)
            b /= np.linalg.norm(b)
        a, b = tuple(a.tolist()), tuple(b.tolist())
        want = np.linalg.norm(quat.angle_axis_difference(np.array(a), np.array(b)), axis=-1)
        assert quat.norm_scalar(quat.angle_axis_difference_scalar(a, b)) == want
