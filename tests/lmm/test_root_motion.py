"""The character root's integration, synchronization and toe shift (plain floats through the scalar forms of
lmm.quat) against a direct definition with lmm.quat's numpy forms, bit for bit (the recordings depend on it)."""
import numpy as np

from lmm import quat
from lmm.mm import MotionMatchingController
from lmm.root_motion import LazyRootShift, _damper_factor, _radians, integrate_root, root_shift, synchronize
from lmm.tuning import Tuning


def _norm(v):
    return float(np.linalg.norm(np.asarray(v, dtype=np.float64), axis=-1))


def _reference_integrate(root_pos, root_rot, vel, ang, dt):
    root_rot = np.array(root_rot)
    vw = quat.mul_vec(root_rot, np.array(vel))
    aw = quat.mul_vec(root_rot, np.array(ang))
    pos = np.array(root_pos) + vw * dt
    rot = quat.normalize(quat.mul(quat.from_scaled_angle_axis(aw * dt), root_rot))
    return [tuple(x.tolist()) for x in (vw, aw, pos, rot)]


def _reference_synchronize(tun, sim_pos, sim_rot, root_pos, root_rot, root_vel_world, root_ang_world, dt):
    """Adjustment and clamping on numpy arrays, as the reference demo writes them."""
    sim_pos, sim_rot, root_pos, root_rot = (np.array(x, dtype=np.float64) for x in (sim_pos, sim_rot, root_pos,
                                                                                   root_rot))
    if tun.adjustment_enabled and dt > 0:
        delta = (sim_pos - root_pos) * _damper_factor(tun.adjustment_position_halflife_s, dt)
        if tun.adjustment_by_velocity:
            cap = tun.adjustment_max_speed_ratio * _norm(root_vel_world) * dt
            length = _norm(delta)
            if length > cap:
                delta = delta * (cap / length)
        root_pos = root_pos + delta
        step = quat.angle_axis_difference(sim_rot, root_rot) * _damper_factor(tun.adjustment_rotation_halflife_s, dt)
        if tun.adjustment_by_velocity:
            cap = tun.adjustment_max_speed_ratio * _norm(root_ang_world) * dt
            length = _norm(step)
            if length > cap:
                step = step * (cap / length)
        root_rot = quat.normalize(quat.mul(quat.from_scaled_angle_axis(step), root_rot))
    if tun.clamping_enabled:
        offset = root_pos - sim_pos
        dist = _norm(offset)
        if dist > tun.clamp_max_distance_m:
            root_pos = sim_pos + offset * (tun.clamp_max_distance_m / dist)
        diff = quat.angle_axis_difference(root_rot, sim_rot)
        angle = _norm(diff)
        max_angle = _radians(tun.clamp_max_angle_deg)
        if angle > max_angle:
            root_rot = quat.normalize(quat.mul(quat.from_scaled_angle_axis(diff * (max_angle / angle)), sim_rot))
    return tuple(root_pos.tolist()), tuple(root_rot.tolist())


class _Sim:
    """The simulation object as either form reads it: arrays, and (position, ..., rotation, ...) tuples."""

    def __init__(self, position, rotation):
        self.position, self.rotation = position, rotation
        self.state = (tuple(position.tolist()), None, None, tuple(rotation.tolist()), None)


def _unit(rng, n):
    q = rng.normal(size=n)
    return q / np.linalg.norm(q)


def test_integration_and_synchronization_equal_the_numpy_definition_bit_for_bit():
    rng = np.random.default_rng(3)
    hits = {"clamp_pos": 0}
    for trial in range(3000):
        tun = Tuning()
        tun.adjustment_enabled = bool(trial % 7)
        tun.adjustment_by_velocity = bool(trial % 3)
        tun.clamping_enabled = bool(trial % 5)
        tun.clamp_max_distance_m = float(rng.uniform(0.01, 0.5))
        tun.clamp_max_angle_deg = float(rng.uniform(1.0, 90.0))
        dt = [1 / 60, 0.0, float(rng.uniform(0.0, 0.1))][trial % 3]
        root_pos = tuple(rng.normal(size=3) * 0.3)
        root_rot = tuple(_unit(rng, 4))
        if trial % 11 == 0:
            root_rot = (-0.0, *root_rot[1:]) if trial % 22 else (root_rot[0], 0.0, 0.0, 0.0)
        vel, ang = tuple(rng.normal(size=3) * rng.uniform(0, 3)), tuple(rng.normal(size=3) * rng.uniform(0, 5))
        if trial % 13 == 0:
            ang = (0.0, 0.0, 0.0)
        got = integrate_root(root_pos, root_rot, vel, ang, dt)
        want = _reference_integrate(root_pos, root_rot, vel, ang, dt)
        assert [tuple(g) for g in got] == [tuple(w) for w in want]
        sim_pos = np.array(root_pos) + rng.normal(size=3) * rng.uniform(0, 0.6)
        sim_rot = np.array(_unit(rng, 4)) if trial % 4 else np.array(root_rot)
        synchronized = synchronize(tun, _Sim(sim_pos, sim_rot).state, got[2], got[3], got[0], got[1], dt)
        ref = _reference_synchronize(tun, sim_pos.tolist(), tuple(sim_rot.tolist()), list(got[2]), got[3],
                                     got[0], got[1], dt)
        assert synchronized == ref
        offset = np.array(ref[0]) - sim_pos
        hits["clamp_pos"] += bool(tun.clamping_enabled and np.isclose(np.linalg.norm(offset),
                                                                      tun.clamp_max_distance_m))
    assert hits["clamp_pos"] > 10


def test_root_shift_in_floats_is_bit_identical_to_the_numpy_form(db, features):
    c = MotionMatchingController(db, features)
    rng = np.random.default_rng(9)
    for _ in range(200):
        c._set_root(rng.normal(size=3).tolist(), quat.normalize(rng.normal(size=4)).tolist())
        position, rotation = rng.normal(size=3), quat.normalize(rng.normal(size=4))
        toes = rng.normal(size=(2, 3))
        want = toes - (position + quat.mul_vec(rotation, quat.inv_mul_vec(c.root_rotation, toes - c.root_position)))
        root = (c._root_position_t, c._root_rotation_t)
        got = np.array(root_shift(*root, [tuple(t) for t in toes.tolist()], position, rotation))
        assert np.array_equal(got, want)
        lazy = LazyRootShift(*root, [tuple(t) for t in toes.tolist()], position, rotation)
        assert np.array_equal(np.array([lazy[1], lazy[0]]), want[::-1])
