"""Foot locking and two-bone leg IK.

Foot locking works on the toe joint (the database's contacts are toe contacts). When a foot's contact
begins, its toe is locked where it is shown at that moment; while locked, the leg is bent by two-bone
IK so the toe stays there. The lock releases when the contact ends or when the animation has carried
the toe further than the unlock radius from the lock; the foot then blends back to the animation with a
critically damped offset (the blend halflife), so nothing pops. Locked toes are kept at least the foot
height above the ground, and the toe is bent up if the tip of the foot (toe length ahead of the toe
joint) would go below the ground.

Everything here is numpy over one pose; the controller calls :func:`foot_lock_update` and
:func:`solve_leg` once per foot per tick.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import math

import numpy as np

from lmm.springs import decay_spring_damper_exact



# One leg is a handful of 3-vectors: plain Python floats are several times faster than numpy calls here.

def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _norm(a):
    return math.sqrt(_dot(a, a))


def _unit(a, fallback=(1.0, 0.0, 0.0)):
    n = _norm(a)
    return (a[0] / n, a[1] / n, a[2] / n) if n > 1e-9 else tuple(fallback)


def _clamp1(x):
    return -1.0 if x < -1.0 else 1.0 if x > 1.0 else x


def _angle_between(u, v) -> float:
    return math.acos(_clamp1(_dot(_unit(u), _unit(v))))


def _axis_angle(axis, angle):
    s = math.sin(angle * 0.5)
    return (math.cos(angle * 0.5), axis[0] * s, axis[1] * s, axis[2] * s)


def _qmul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def _qrot(q, v):
    w, x, y, z = q
    t = _cross((x, y, z), v)
    t = (2.0 * t[0], 2.0 * t[1], 2.0 * t[2])
    u = _cross((x, y, z), t)
    return (v[0] + w * t[0] + u[0], v[1] + w * t[1] + u[1], v[2] + w * t[2] + u[2])


def _qnormalize(q):
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def two_bone_ik(hip_pos, knee_pos, ankle_pos, target, hip_rot, knee_rot, eps: float = 1e-4):
    """Global rotations (hip, knee) that bring the ankle onto ``target`` (or as close as the leg reaches).

    Law of cosines: first the knee is bent (and the hip swung in the leg's plane) so the hip-ankle
    distance equals the hip-target distance, then the hip turns the leg onto the target. The leg's
    plane is kept (no twist); a straight leg bends in the plane of its knee's local Z axis.
    Returns two (4,) arrays.
    """
    a, b, c, t = (tuple(float(v) for v in x) for x in (hip_pos, knee_pos, ankle_pos, target))
    hip_rot = tuple(float(v) for v in hip_rot)
    knee_rot = tuple(float(v) for v in knee_rot)
    ab, cb, ac, at = _sub(b, a), _sub(b, c), _sub(c, a), _sub(t, a)
    l_ab, l_cb = _norm(ab), _norm(cb)
    l_at = min(max(_norm(at), eps), l_ab + l_cb - eps)

    ac_ab_0 = _angle_between(ac, ab)
    ba_bc_0 = _angle_between(_sub(a, b), _sub(c, b))
    ac_at_0 = _angle_between(ac, at)
    ac_ab_1 = math.acos(_clamp1((l_cb * l_cb - l_ab * l_ab - l_at * l_at) / (-2.0 * l_ab * l_at)))
    ba_bc_1 = math.acos(_clamp1((l_at * l_at - l_ab * l_ab - l_cb * l_cb) / (-2.0 * l_ab * l_cb)))

    bend_axis = _cross(ac, ab)
    if _norm(bend_axis) < 1e-9:  # straight leg: bend about the knee's own Z axis
        bend_axis = _qrot(knee_rot, (0.0, 0.0, 1.0))
    bend_axis = _unit(bend_axis)
    turn_axis = _unit(_cross(ac, at), fallback=bend_axis)

    r0 = _axis_angle(bend_axis, ac_ab_1 - ac_ab_0)
    r1 = _axis_angle(bend_axis, ba_bc_1 - ba_bc_0)
    r2 = _axis_angle(turn_axis, ac_at_0)
    hip_new = _qmul(r2, _qmul(r0, hip_rot))
    knee_new = _qmul(r2, _qmul(r0, _qmul(r1, knee_rot)))
    return np.array(_qnormalize(hip_new)), np.array(_qnormalize(knee_new))


@dataclass
class FootLockState:
    """Per foot (left, right): lock flag and position, the blend-out offset after an unlock, and whether
    the foot was released by distance during the current contact (it is not locked again before the
    contact ends)."""
    locked: np.ndarray = field(default_factory=lambda: np.zeros(2, dtype=bool))
    lock_position: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))
    offset_position: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))
    offset_velocity: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))
    released: np.ndarray = field(default_factory=lambda: np.zeros(2, dtype=bool))  # unlocked by distance
    previous_target: np.ndarray | None = None

    def copy(self) -> "FootLockState":
        return FootLockState(self.locked.copy(), self.lock_position.copy(), self.offset_position.copy(),
                             self.offset_velocity.copy(), self.released.copy(),
                             None if self.previous_target is None else self.previous_target.copy())


def foot_lock_update(state: FootLockState, toe_positions, toe_velocities, contacts, unlock_radius: float,
                     blend_halflife: float, foot_height: float, dt: float) -> tuple[FootLockState, np.ndarray]:
    """Advance the locks one tick. Returns the new state and the toe targets (2, 3), world space."""
    toe_positions = np.asarray(toe_positions, dtype=np.float64)
    toe_velocities = np.asarray(toe_velocities, dtype=np.float64)
    contacts = np.asarray(contacts, dtype=bool)
    s = state.copy()
    s.offset_position, s.offset_velocity = decay_spring_damper_exact(
        s.offset_position, s.offset_velocity, blend_halflife, dt)
    targets = np.empty((2, 3))
    for i in range(2):
        anim = toe_positions[i]
        if not contacts[i]:
            s.released[i] = False
        if s.locked[i]:
            far = _norm(tuple(float(v) for v in anim - s.lock_position[i])) > unlock_radius
            if not contacts[i] or far:
                # unlock: carry the lock as an offset that blends back to the animation
                s.locked[i] = False
                s.released[i] = bool(contacts[i])  # stays free until this contact ends
                s.offset_position[i] = s.lock_position[i] - anim
                s.offset_velocity[i] = -toe_velocities[i]
        elif contacts[i] and not s.released[i]:
            # in contact (it began, or a transition brought one): lock where the toe is shown now,
            # so the lock itself does not pop
            s.locked[i] = True
            shown = anim + s.offset_position[i]
            shown[1] = max(shown[1], foot_height)
            s.lock_position[i] = shown
            s.offset_position[i] = 0.0
            s.offset_velocity[i] = 0.0
        targets[i] = s.lock_position[i] if s.locked[i] else anim + s.offset_position[i]
    s.previous_target = targets.copy()
    return s, targets


def toe_clear_ground(toe_pos, toe_rot, toe_axis_local, toe_length: float, ground_height: float):
    """The toe's global rotation bent up (about the horizontal axis across the foot) so the tip of the
    foot, ``toe_length`` along ``toe_axis_local`` from the toe joint, is not below ``ground_height``."""
    if toe_length <= 0.0:
        return toe_rot
    q = tuple(float(v) for v in toe_rot)
    d = _unit(_qrot(q, tuple(float(v) for v in toe_axis_local)))
    if float(toe_pos[1]) + toe_length * d[1] >= ground_height:
        return toe_rot
    want = _clamp1((ground_height - float(toe_pos[1])) / toe_length)
    angle = math.asin(want) - math.asin(_clamp1(d[1]))
    axis = _cross(d, (0.0, 1.0, 0.0))
    if _norm(axis) < 1e-9:
        return toe_rot
    return np.array(_qnormalize(_qmul(_axis_angle(_unit(axis), angle), q)))


def solve_leg(global_pos, global_rot, chain, toe_target, toe_axis_local, toe_length: float,
              ground_height: float | None):
    """New global rotations for (hip, knee, foot, toe) of one leg so the toe reaches ``toe_target``.

    ``chain`` = (hip, knee, foot, toe) bone indices. The foot keeps its global rotation (so the toe's
    offset from the ankle is unchanged); the ankle's target is the toe target minus that offset.
    Returns a dict bone -> new global rotation.
    """
    hip, knee, foot, toe = chain
    ankle_target = toe_target - (global_pos[toe] - global_pos[foot])
    hip_rot, knee_rot = two_bone_ik(global_pos[hip], global_pos[knee], global_pos[foot], ankle_target,
                                    global_rot[hip], global_rot[knee])
    out = {hip: hip_rot, knee: knee_rot, foot: global_rot[foot]}
    toe_rot = global_rot[toe]
    if ground_height is not None:
        toe_rot = toe_clear_ground(toe_target, toe_rot, toe_axis_local, toe_length, ground_height)
    out[toe] = toe_rot
    return out


def local_rotations_from_global(global_rot, parents, bones) -> dict:
    """Local rotations (parent^-1 * global) of the given bones of one pose, as (4,) arrays."""
    out = {}
    for j in bones:
        pw, px, py, pz = (float(v) for v in global_rot[parents[j]])
        out[j] = np.array(_qmul((pw, -px, -py, -pz), tuple(float(v) for v in global_rot[j])))
    return out

