"""The character root each tick: integrated from the pose's root velocities (:func:`integrate_root`),
then pulled towards the simulation object (adjustment) and kept near it (clamping) by :func:`synchronize`;
:func:`root_shift` is how far that moved the toes (the foot locks keep a foot near the ground from
following it). One position and one quaternion in plain floats through the scalar forms of :mod:`lmm.quat`."""
from __future__ import annotations

import math

import numpy as np

from lmm import quat
from lmm.springs import damper_factor


_DAMPER_FACTORS: dict = {}
_RADIANS: dict = {}


def _damper_factor(halflife: float, dt: float) -> float:
    """1 - exp(-ln2 dt / halflife) (numpy's exp), remembered per (halflife, dt): a tuning changes rarely."""
    key = (halflife, dt)
    f = _DAMPER_FACTORS.get(key)
    if f is None:
        if len(_DAMPER_FACTORS) > 64:
            _DAMPER_FACTORS.clear()
        f = _DAMPER_FACTORS[key] = float(damper_factor(halflife, dt))
    return f


def integrate_root(root_pos, root_rot, vel, ang, dt) -> tuple:
    """The character root moved by its local velocity ``vel`` and angular velocity ``ang`` (3 floats each)
    for ``dt``: (world velocity, world angular velocity, position, rotation)."""
    vw = quat.mul_vec_scalar(root_rot, vel)
    aw = quat.mul_vec_scalar(root_rot, ang)
    pos = (root_pos[0] + vw[0] * dt, root_pos[1] + vw[1] * dt, root_pos[2] + vw[2] * dt)
    rot = quat.normalize_scalar(quat.mul_scalar(
        quat.from_scaled_angle_axis_scalar((aw[0] * dt, aw[1] * dt, aw[2] * dt)), root_rot))
    return vw, aw, pos, rot


def _radians(degrees: float) -> float:
    """``float(np.radians(degrees))``, remembered per value."""
    r = _RADIANS.get(degrees)
    if r is None:
        if len(_RADIANS) > 64:
            _RADIANS.clear()
        r = _RADIANS[degrees] = float(np.radians(degrees))
    return r


def _capped(d, velocity, ratio: float, dt: float) -> tuple:
    """The step ``d`` shortened to at most ``ratio * |velocity| * dt`` (adjustment by velocity)."""
    dx, dy, dz = d
    vx, vy, vz = velocity
    cap = ratio * math.sqrt(vx * vx + vy * vy + vz * vz) * dt
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    if length > cap:
        k = cap / length
        return dx * k, dy * k, dz * k
    return dx, dy, dz


def synchronize(tun, sim_state, root_pos, root_rot, root_vel_world, root_ang_world, dt) -> tuple:
    """Adjustment (pull the integrated character root ``root_pos``/``root_rot``, floats, towards the
    simulation object, ``sim_state`` as :class:`lmm.trajectory.SimulationState` keeps it) and clamping:
    the character root's new (position, rotation) as tuples. Plain floats (one position and one
    quaternion), a fraction of the time of numpy calls (tests/lmm/test_root_motion.py checks it against numpy)."""
    (sx, sy, sz), sim_rot = sim_state[0], sim_state[3]
    px, py, pz = root_pos
    rw, rx, ry, rz = root_rot
    if tun.adjustment_enabled and dt > 0:
        factor = _damper_factor(tun.adjustment_position_halflife_s, dt)
        dx, dy, dz = (sx - px) * factor, (sy - py) * factor, (sz - pz) * factor
        if tun.adjustment_by_velocity:
            dx, dy, dz = _capped((dx, dy, dz), root_vel_world, tun.adjustment_max_speed_ratio, dt)
        px, py, pz = px + dx, py + dy, pz + dz
        dx, dy, dz = quat.angle_axis_difference_scalar(sim_rot, (rw, rx, ry, rz))
        factor = _damper_factor(tun.adjustment_rotation_halflife_s, dt)
        dx, dy, dz = dx * factor, dy * factor, dz * factor
        if tun.adjustment_by_velocity:
            dx, dy, dz = _capped((dx, dy, dz), root_ang_world, tun.adjustment_max_speed_ratio, dt)
        rw, rx, ry, rz = quat.normalize_scalar(quat.mul_scalar(quat.from_scaled_angle_axis_scalar((dx, dy, dz)),
                                                               (rw, rx, ry, rz)))
    if tun.clamping_enabled:
        ox, oy, oz = px - sx, py - sy, pz - sz
        dist = math.sqrt(ox * ox + oy * oy + oz * oz)
        max_dist = tun.clamp_max_distance_m
        if dist > max_dist:
            k = max_dist / dist
            px, py, pz = sx + ox * k, sy + oy * k, sz + oz * k
        dx, dy, dz = quat.angle_axis_difference_scalar((rw, rx, ry, rz), sim_rot)
        angle = math.sqrt(dx * dx + dy * dy + dz * dz)
        max_angle = _radians(tun.clamp_max_angle_deg)
        if angle > max_angle:
            k = max_angle / angle
            rw, rx, ry, rz = quat.normalize_scalar(quat.mul_scalar(
                quat.from_scaled_angle_axis_scalar((dx * k, dy * k, dz * k)), sim_rot))
    return (px, py, pz), (rw, rx, ry, rz)


def root_shift(root_position, root_rotation, toes, position, rotation) -> list:
    """How far adjustment and clamping moved each toe this tick (two 3-tuples; ``toes`` two 3-tuples):
    the toes as shown minus where they would be with the root left at ``position``/``rotation`` (the
    integrated root). Plain floats, the operations of ``toes - (position + quat.mul_vec(rotation,
    quat.inv_mul_vec(root_rotation, toes - root_position)))`` (``root_*``: the root as shown, tuples)."""
    px, py, pz = root_position
    root_rot = root_rotation
    ox, oy, oz = position.tolist() if isinstance(position, np.ndarray) else position
    rotation = rotation.tolist() if isinstance(rotation, np.ndarray) else rotation
    out = []
    for t in toes:
        back = quat.mul_vec_scalar(rotation, quat.inv_mul_vec_scalar(root_rot, (t[0] - px, t[1] - py, t[2] - pz)))
        out.append((t[0] - (ox + back[0]), t[1] - (oy + back[1]), t[2] - (oz + back[2])))
    return out


class LazyRootShift:
    """``root_shift(root_position, root_rotation, toes, position, rotation)[i]`` worked out when item ``i``
    is read (the foot locks read it only for an unlocked foot near the ground): the same floats, often none
    computed."""
    __slots__ = ("_args", "_toes")

    def __init__(self, root_position, root_rotation, toes, position, rotation):
        self._args, self._toes = (root_position, root_rotation, position, rotation), toes

    def __getitem__(self, i: int):
        root_position, root_rotation, position, rotation = self._args
        return root_shift(root_position, root_rotation, (self._toes[i],), position, rotation)[0]
