"""The character root's integration and synchronization in written-out floats equal the quat_scalar forms
bit for bit (the recordings depend on it)."""
import numpy as np

from lmm import quat_scalar as qs
from lmm.character import CharacterController, _damper_factor, _integrate_root_f, _radians
from lmm.tuning import Tuning


def _reference_integrate(root_pos, root_rot, vel, ang, dt):
    vw = qs.mul_vec(root_rot, vel)
    aw = qs.mul_vec(root_rot, ang)
    pos = [p + v * dt for p, v in zip(root_pos, vw)]
    rot = qs.normalize(qs.mul(qs.from_scaled_angle_axis([w * dt for w in aw]), root_rot))
    return vw, aw, pos, rot


def _reference_synchronize(tun, sim_pos, sim_rot, root_pos, root_rot, root_vel_world, root_ang_world, dt):
    """The quat_scalar form the written-out CharacterController._synchronize replaces."""
    if tun.adjustment_enabled and dt > 0:
        factor = _damper_factor(tun.adjustment_position_halflife_s, dt)
        delta = [(s - r) * factor for s, r in zip(sim_pos, root_pos)]
        if tun.adjustment_by_velocity:
            cap = tun.adjustment_max_speed_ratio * qs.norm(root_vel_world) * dt
            length = qs.norm(delta)
            if length > cap:
                delta = [d * (cap / length) for d in delta]
        root_pos = [r + d for r, d in zip(root_pos, delta)]
        diff = qs.to_scaled_angle_axis(qs.abs_(qs.mul_inv(sim_rot, root_rot)))
        factor = _damper_factor(tun.adjustment_rotation_halflife_s, dt)
        step = [d * factor for d in diff]
        if tun.adjustment_by_velocity:
            cap = tun.adjustment_max_speed_ratio * qs.norm(root_ang_world) * dt
            length = qs.norm(step)
            if length > cap:
                step = [d * (cap / length) for d in step]
        root_rot = qs.normalize(qs.mul(qs.from_scaled_angle_axis(step), root_rot))
    if tun.clamping_enabled:
        offset = [r - s for r, s in zip(root_pos, sim_pos)]
        dist = qs.norm(offset)
        if dist > tun.clamp_max_distance_m:
            root_pos = [s + o * (tun.clamp_max_distance_m / dist) for s, o in zip(sim_pos, offset)]
        diff = qs.to_scaled_angle_axis(qs.abs_(qs.mul_inv(root_rot, sim_rot)))
        angle = qs.norm(diff)
        max_angle = _radians(tun.clamp_max_angle_deg)
        if angle > max_angle:
            root_rot = qs.normalize(qs.mul(qs.from_scaled_angle_axis([d * (max_angle / angle) for d in diff]),
                                           sim_rot))
    return tuple(root_pos), tuple(root_rot)


class _Sim:
    """The simulation object as either form reads it: arrays, and (position, ..., rotation, ...) tuples."""

    def __init__(self, position, rotation):
        self.position, self.rotation = position, rotation
        self.state = (tuple(position.tolist()), None, None, tuple(rotation.tolist()), None)


class _Root:
    """Just what _synchronize reads and writes."""

    def __init__(self, tun, sim):
        self.tuning, self.sim = tun, sim

    def _set_root(self, position, rotation):
        self.got = (tuple(position), tuple(rotation))


def _unit(rng, n):
    q = rng.normal(size=n)
    return q / np.linalg.norm(q)


def test_integration_and_synchronization_equal_the_quat_scalar_forms_bit_for_bit():
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
        got = _integrate_root_f(root_pos, root_rot, vel, ang, dt)
        want = _reference_integrate(root_pos, root_rot, vel, ang, dt)
        assert [tuple(g) for g in got] == [tuple(w) for w in want]
        sim_pos = np.array(root_pos) + rng.normal(size=3) * rng.uniform(0, 0.6)
        sim_rot = np.array(_unit(rng, 4)) if trial % 4 else np.array(root_rot)
        fake = _Root(tun, _Sim(sim_pos, sim_rot))
        CharacterController._synchronize(fake, got[2], got[3], got[0], got[1], dt)
        ref = _reference_synchronize(tun, sim_pos.tolist(), tuple(sim_rot.tolist()), list(got[2]), got[3],
                                     got[0], got[1], dt)
        assert fake.got == ref
        offset = np.array(ref[0]) - sim_pos
        hits["clamp_pos"] += bool(tun.clamping_enabled and np.isclose(np.linalg.norm(offset),
                                                                      tun.clamp_max_distance_m))
    assert hits["clamp_pos"] > 10
