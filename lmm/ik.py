"""Foot locking and two-bone leg IK.

Foot locking works on the toe joint (the database's contacts are toe contacts). When a foot's contact
begins, its toe is locked where it is shown at that moment; while locked, the leg is bent by two-bone
IK so the toe stays there. The lock holds while the animation's contact lasts and until the animation
lifts the toe after it (the unlock radius only as a last resort, then the foot steps); the foot then
blends back to the animation with a critically damped offset that may not glide along the ground, so
nothing pops and nothing skates (see :func:`foot_lock_update`). Locked toes are kept at least the foot
height above the ground, and the toe is bent up if the tip of the foot (toe length ahead of the toe
joint) would go below the ground.

Everything here is numpy over one pose; the controller calls :func:`foot_lock_update` and
:func:`solve_leg` once per foot per tick.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import math

import numpy as np



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
    """Per foot (left, right): lock flag and position, the lowest height of the animated toe while locked,
    the offset (target minus animated toe) that blends out after an unlock and its velocity, and whether
    the foot was released by the unlock radius during the current contact (it is not locked again before
    that contact ends)."""
    locked: np.ndarray = field(default_factory=lambda: np.zeros(2, dtype=bool))
    lock_position: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))
    offset_position: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))
    offset_velocity: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))
    released: np.ndarray = field(default_factory=lambda: np.zeros(2, dtype=bool))  # unlocked by distance
    previous_target: np.ndarray | None = None
    lowest_animated: np.ndarray = field(default_factory=lambda: np.zeros(2))

    def copy(self) -> "FootLockState":
        return FootLockState(self.locked.copy(), self.lock_position.copy(), self.offset_position.copy(),
                             self.offset_velocity.copy(), self.released.copy(),
                             None if self.previous_target is None else self.previous_target.copy(),
                             self.lowest_animated.copy())


def _decay(x: float, v: float, y: float, e: float, dt: float) -> tuple[float, float]:
    """One component of a critically damped decay towards zero (damping ``y``, ``e = exp(-y dt)``)."""
    j1 = v + x * y
    return e * (x + j1 * dt), e * (v - j1 * y * dt)


SWING_SPEEDS_M_S = (0.5, 1.5)  # horizontal toe speed where the swing clearance starts and is complete


def swing_floor(speed: float, foot_height: float, clearance: float) -> float:
    """Lowest height (m) of an unlocked toe moving ``speed`` m/s horizontally: ``foot_height`` (never
    through the floor) plus ``clearance`` faded in with speed (smoothstep over :data:`SWING_SPEEDS_M_S`),
    so a foot landing or shuffling slowly is left alone and a fast swing does not skim the ground."""
    lo, hi = SWING_SPEEDS_M_S
    t = min(max((speed - lo) / (hi - lo), 0.0), 1.0)
    return foot_height + clearance * t * t * (3.0 - 2.0 * t)


def soft_floor(y: float, floor: float, softness: float = 0.01) -> float:
    """``max(y, floor)`` with a rounded corner (C1, exact outside ``floor +- softness``): a toe coming
    down onto its floor slows instead of stopping dead."""
    if y >= floor + softness:
        return y
    if y <= floor - softness:
        return floor
    d = y - floor + softness
    return floor + d * d / (4.0 * softness)


def foot_lock_update(state: FootLockState, toe_positions, toe_velocities, contacts, unlock_radius: float,
                     blend_halflife: float, foot_height: float, dt: float, lift_height: float = 0.02,
                     ground_blend_speed: float = 0.1, step_height: float = 0.04,
                     root_shift=None, swing_clearance: float = 0.0) -> tuple[FootLockState, np.ndarray]:
    """Advance the locks one tick. Returns the new state and the toe targets (2, 3), world space.

    The rule, per foot:

    * **lock** when the animation's contact begins, where the toe is shown at that moment (so the lock
      does not pop), at least ``foot_height`` above the ground (y = 0);
    * **hold** while the contact lasts, and after it ends until the animated toe has risen
      ``lift_height`` above its lowest point during the lock: the foot leaves the ground when the
      animation lifts it, not earlier;
    * **last resort**: release when the animated toe is further than ``unlock_radius`` (horizontally)
      from the lock; the foot then steps to the animation (its blend gets an upward kick of about
      ``step_height``) instead of sliding there, and locks again where it comes down if the contact
      still holds;
    * **blend back** after a release: the target is the animated toe plus an offset that decays with a
      critically damped spring (``blend_halflife``), starting at the lock with zero velocity. While the
      target is near the ground (less than ``lift_height`` above the last lock) the offset may move
      horizontally at most ``ground_blend_speed``: the rest is absorbed once the foot is in the air (or
      by the next lock, which starts where the foot is shown).
    * **not dragged by the root**: ``root_shift`` (2, 3), when given, is how far this tick's root
      adjustment and clamping moved each animated toe. An unlocked foot near the ground does not follow
      it horizontally (it goes into the offset, at most ``unlock_radius`` of it, and is blended out under
      the same ground speed limit); a locked foot is held anyway.
    """
    anim = [tuple(float(v) for v in p) for p in np.asarray(toe_positions, dtype=np.float64)]
    vel = [tuple(float(v) for v in p) for p in np.asarray(toe_velocities, dtype=np.float64)]
    contacts = [bool(c) for c in np.asarray(contacts, dtype=bool)]
    locked = [bool(v) for v in state.locked]
    released = [bool(v) for v in state.released]
    lowest = [float(v) for v in state.lowest_animated]
    lock = [tuple(float(v) for v in p) for p in state.lock_position]
    off = [list(float(v) for v in p) for p in state.offset_position]
    off_v = [list(float(v) for v in p) for p in state.offset_velocity]
    y = 2.0 * math.log(2.0) / (blend_halflife + 1e-5)  # halflife_to_damping / 2
    e = math.exp(-y * dt)
    targets = []
    for i in range(2):
        a, c = anim[i], contacts[i]
        if not c:
            released[i] = False
        elif released[i] and (off_v[i][1] < 0.0 and off[i][1] < 0.25 * step_height if step_height > 0.0
                              else abs(off[i][0]) + abs(off[i][1]) + abs(off[i][2]) < 0.01):
            released[i] = False  # the step after a last-resort release has come down: lock again
        if locked[i]:
            lx, ly, lz = lock[i]
            lowest[i] = min(lowest[i], a[1])
            far = math.hypot(a[0] - lx, a[2] - lz) > unlock_radius
            if far or (not c and a[1] > lowest[i] + lift_height):
                # release: the offset carries the target from the lock (at rest) back to the animation
                locked[i] = False
                released[i] = c
                off[i] = [lx - a[0], ly - a[1], lz - a[2]]
                off_v[i] = [-vel[i][0], -vel[i][1], -vel[i][2]]
                if far and step_height > 0.0:
                    # an upward kick whose critically damped arc peaks at about step_height: x(t) = V t e^-yt
                    off_v[i][1] += step_height * y * math.e
                targets.append(lock[i])  # this tick the foot is still where it was locked
                continue
        elif c and not released[i]:
            # a contact (it began, or a transition brought one): lock where the toe is shown now
            shown = (a[0] + off[i][0], max(a[1] + off[i][1], foot_height), a[2] + off[i][2])
            locked[i] = True
            lock[i] = shown
            lowest[i] = a[1]
            off[i] = [0.0, 0.0, 0.0]
            off_v[i] = [0.0, 0.0, 0.0]
        if locked[i]:
            targets.append(lock[i])
            continue
        if root_shift is not None and a[1] + off[i][1] < lock[i][1] + lift_height:
            # the root was pulled towards the simulation object: a foot near the ground stays put
            cx, cz = off[i][0] - float(root_shift[i][0]), off[i][2] - float(root_shift[i][2])
            n = math.hypot(cx, cz)
            if n > unlock_radius:
                cx, cz = (cx * unlock_radius / n, cz * unlock_radius / n) if n > 0.0 else (0.0, 0.0)
            off[i][0], off[i][2] = cx, cz
        ox, oy, oz = off[i]
        vx, vy, vz = off_v[i]
        nx, vx = _decay(ox, vx, y, e, dt)
        ny, vy = _decay(oy, vy, y, e, dt)
        nz, vz = _decay(oz, vz, y, e, dt)
        if a[1] + ny < lock[i][1] + lift_height and dt > 0.0:
            # near the ground: the blend may not glide the foot faster than ground_blend_speed
            step = math.hypot(nx - ox, nz - oz)
            cap = ground_blend_speed * dt
            if step > cap:
                k = cap / step
                nx, nz = ox + (nx - ox) * k, oz + (nz - oz) * k
                vx, vz = (nx - ox) / dt, (nz - oz) / dt
        off[i] = [nx, ny, nz]
        off_v[i] = [vx, vy, vz]
        ty = a[1] + ny
        if swing_clearance > 0.0:
            ty = soft_floor(ty, swing_floor(math.hypot(vel[i][0], vel[i][2]), foot_height, swing_clearance))
        targets.append((a[0] + nx, ty, a[2] + nz))
    t = np.array(targets)
    s = FootLockState(np.array(locked), np.array(lock, dtype=np.float64), np.array(off, dtype=np.float64),
                      np.array(off_v, dtype=np.float64), np.array(released), t.copy(), np.array(lowest))
    return s, t


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

