"""Foot locking and two-bone leg IK.

Foot locking works on the toe joint (the database's contacts are toe contacts). When a foot's contact
begins, its toe is locked where it is shown at that moment; while locked, the leg is bent by two-bone
IK so the toe stays there. The lock holds while the animation's contact lasts and until the animation
lifts the toe after it (the unlock radius only as a last resort, then the foot steps); the foot then
blends back to the animation with a critically damped offset that may not glide along the ground, so
nothing pops and nothing skates (see :func:`foot_lock_update`). Locked toes are kept at least the foot
height above the ground, and the toe is bent up if the tip of the foot (toe length ahead of the toe
joint) would go below the ground.

One pose's worth of 3-vectors and quaternions is done in plain Python floats (tuples): several
times faster than numpy calls on tiny arrays. The controller calls :meth:`FootLockState.update` and
:func:`solve_legs` once per tick on a pose kept as lists of tuples; :func:`foot_lock_update` is the
lock update as a function of a state it leaves alone.
"""
from __future__ import annotations

import copy
import math

import numpy as np

from lmm import quat
from lmm.springs import decay_spring_damper_scalar, halflife_to_damping

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


def soft_reach(d: float, l_ab: float, l_cb: float, n_ac: float, min_knee_cos: float = 1.0,
               soft: float = 0.0) -> float:
    """The hip-ankle distance the leg is given for a target ``d`` away: ``d`` itself up to the start of
    the soft zone, then an exponential approach to the longest leg allowed, so the knee straightens
    ever more slowly instead of locking straight (the knee angle is very sensitive to the distance near
    full extension: 1 cm short of straight is about 18 degrees of knee). The longest leg has the knee bent
    at the angle whose cosine is ``min_knee_cos`` (the data's straightest knee: an animated leg straighter
    than that, from a blend, is bent to it too); the soft zone is ``soft`` metres below it but never
    starts before the animated leg's length ``n_ac``, so a target where the animation puts the ankle
    leaves the leg as it is (unless it is too straight). C1."""
    if soft <= 0.0 and min_knee_cos >= 1.0:
        return d
    longest = math.sqrt(l_ab * l_ab + l_cb * l_cb + 2.0 * l_ab * l_cb * min_knee_cos)
    start = max(longest - soft, min(n_ac, longest))
    if d <= start:
        return d
    width = longest - start
    if width <= 1e-9:
        return longest
    return start + width * (1.0 - math.exp(-(d - start) / width))


class KneeLimiter:
    """Keeps one knee's angle from accelerating harder than ``max_acceleration`` (rad/s^2): the IK's
    knee follows the angle it is asked for exactly while that moves within the limit (the animation
    does: the data's own knees stay under it), and catches up with a bounded acceleration and no
    overshoot when asked to jump (a lock letting go of a stretched leg, a target that moves fast near
    full extension, where a centimetre is many degrees of knee). Angles are knee flexion (0 straight)."""
    __slots__ = ("angle", "velocity", "asked")

    def __init__(self):
        self.angle = None      # the last angle given, None before the first
        self.velocity = 0.0
        self.asked = 0.0       # the last angle asked for

    def step(self, asked: float, dt: float, max_acceleration: float) -> float:
        if self.angle is None or dt <= 0.0 or max_acceleration <= 0.0:
            self.angle, self.velocity, self.asked = asked, 0.0, asked
            return asked
        moving = (asked - self.asked) / dt                # the asked angle's own velocity
        gap = asked - self.angle                          # to land on it this tick: gap / dt; closing on it
        # no faster than it can stop in time, one tick of reaction included: v^2 / 2a + v dt <= |gap|
        brake = max_acceleration * (math.sqrt(dt * dt + 2.0 * abs(gap) / max_acceleration) - dt)
        wanted = moving + max(-brake, min(brake, gap / dt - moving))
        dv = max(-max_acceleration * dt, min(max_acceleration * dt, wanted - self.velocity))
        self.velocity += dv
        self.angle += self.velocity * dt
        self.asked = asked
        return self.angle

    def track(self, angle: float, dt: float) -> None:
        """The leg was left to the animation this tick: follow it (its velocity too)."""
        if self.angle is not None and dt > 0.0:
            self.velocity = (angle - self.angle) / dt
        self.angle = self.asked = angle

    def settled(self, angle: float, tolerance: float = 1e-4) -> bool:
        """Whether it gives ``angle`` as asked (it trails by less than ``tolerance`` rad)."""
        return self.angle is None or abs(self.angle - angle) < tolerance


def knee_flexion(l_ab: float, l_cb: float, l_ac: float) -> float:
    """Knee flexion (rad, 0 straight) of a leg whose hip and ankle are ``l_ac`` apart (law of cosines)."""
    c = (l_ab * l_ab + l_cb * l_cb - l_ac * l_ac) / (2.0 * l_ab * l_cb)
    return math.pi - math.acos(-1.0 if c < -1.0 else 1.0 if c > 1.0 else c)


def two_bone_ik(a, b, c, t, hip_rot, knee_rot, eps: float = 1e-4, min_knee_cos: float = 1.0,
                soft: float = 0.0, knee=None):
    """Global rotations (hip, knee) that bring the ankle ``c`` onto the target ``t`` (or as close as the leg
    reaches); ``a``/``b`` the hip and knee positions. Sequences of floats in (positions 3, rotations 4),
    two 4-tuples out. ``min_knee_cos`` and ``soft``: the reach limit (:func:`soft_reach`); the defaults
    (1, 0) reach to full extension. ``knee``: None, or a function of the knee flexion asked for (rad)
    giving the one to use (:class:`KneeLimiter`); the hip still aims the ankle at the target.

    Law of cosines: first the knee is bent (and the hip swung in the leg's plane) so the hip-ankle
    distance equals the hip-target distance, then the hip turns the leg onto the target. The leg's
    plane is kept (no twist); a straight leg bends in the plane of its knee's local Z axis.
    Written out per component (tests/lmm/test_ik.py checks it against a helper-per-3-vector form): ``a - b``
    is exactly ``-(b - a)``, so the knee's angle reuses the thigh and shin directions."""
    a0, a1, a2 = a
    b0, b1, b2 = b
    c0, c1, c2 = c
    ab0, ab1, ab2 = b0 - a0, b1 - a1, b2 - a2
    cb0, cb1, cb2 = b0 - c0, b1 - c1, b2 - c2
    ac0, ac1, ac2 = c0 - a0, c1 - a1, c2 - a2
    at0, at1, at2 = t[0] - a0, t[1] - a1, t[2] - a2
    l_ab = math.sqrt(ab0 * ab0 + ab1 * ab1 + ab2 * ab2)
    l_cb = math.sqrt(cb0 * cb0 + cb1 * cb1 + cb2 * cb2)
    n_at = math.sqrt(at0 * at0 + at1 * at1 + at2 * at2)
    n_ac = math.sqrt(ac0 * ac0 + ac1 * ac1 + ac2 * ac2)
    l_at = min(max(soft_reach(n_at, l_ab, l_cb, n_ac, min_knee_cos, soft), eps), l_ab + l_cb - eps)
    if knee is not None and l_ab > 1e-9 and l_cb > 1e-9:
        asked = knee_flexion(l_ab, l_cb, l_at)
        bent = max(knee(asked), math.acos(min_knee_cos))   # never straighter than the limit
        l_at = min(max(math.sqrt(max(l_ab * l_ab + l_cb * l_cb + 2.0 * l_ab * l_cb * math.cos(bent), 0.0)), eps),
                   l_ab + l_cb - eps)

    # unit vectors (_unit: (1, 0, 0) for a null vector) and the angles between them (_angle_between,
    # the cosine clamped to [-1, 1] as _clamp1 does)
    if l_ab > 1e-9:
        uab0, uab1, uab2 = ab0 / l_ab, ab1 / l_ab, ab2 / l_ab
    else:
        uab0, uab1, uab2 = 1.0, 0.0, 0.0
    if n_ac > 1e-9:
        uac0, uac1, uac2 = ac0 / n_ac, ac1 / n_ac, ac2 / n_ac
    else:
        uac0, uac1, uac2 = 1.0, 0.0, 0.0
    if n_at > 1e-9:
        uat0, uat1, uat2 = at0 / n_at, at1 / n_at, at2 / n_at
    else:
        uat0, uat1, uat2 = 1.0, 0.0, 0.0
    d = uac0 * uab0 + uac1 * uab1 + uac2 * uab2
    ac_ab_0 = math.acos(-1.0 if d < -1.0 else 1.0 if d > 1.0 else d)
    if l_ab > 1e-9 and l_cb > 1e-9:  # unit(a - b) . unit(c - b) = (-u_ab) . (-u_cb), bit for bit
        d = uab0 * (cb0 / l_cb) + uab1 * (cb1 / l_cb) + uab2 * (cb2 / l_cb)
        ba_bc_0 = math.acos(-1.0 if d < -1.0 else 1.0 if d > 1.0 else d)
    else:
        ba_bc_0 = _angle_between(_sub(a, b), _sub(c, b))
    d = uac0 * uat0 + uac1 * uat1 + uac2 * uat2
    ac_at_0 = math.acos(-1.0 if d < -1.0 else 1.0 if d > 1.0 else d)
    d = (l_cb * l_cb - l_ab * l_ab - l_at * l_at) / (-2.0 * l_ab * l_at)
    ac_ab_1 = math.acos(-1.0 if d < -1.0 else 1.0 if d > 1.0 else d)
    d = (l_at * l_at - l_ab * l_ab - l_cb * l_cb) / (-2.0 * l_ab * l_cb)
    ba_bc_1 = math.acos(-1.0 if d < -1.0 else 1.0 if d > 1.0 else d)

    # bend axis: ac x ab (a straight leg bends about the knee's own Z axis)
    x, y, z = ac1 * ab2 - ac2 * ab1, ac2 * ab0 - ac0 * ab2, ac0 * ab1 - ac1 * ab0
    n = math.sqrt(x * x + y * y + z * z)
    if n < 1e-9:
        x, y, z = quat.mul_vec_scalar(knee_rot, (0.0, 0.0, 1.0))
        n = math.sqrt(x * x + y * y + z * z)
    bend = (x / n, y / n, z / n) if n > 1e-9 else (1.0, 0.0, 0.0)
    # turn axis: ac x at
    x, y, z = ac1 * at2 - ac2 * at1, ac2 * at0 - ac0 * at2, ac0 * at1 - ac1 * at0
    n = math.sqrt(x * x + y * y + z * z)
    turn = (x / n, y / n, z / n) if n > 1e-9 else bend

    # r0, r1 about the bend axis, r2 about the turn axis; hip = r2 r0 hip_rot, knee = r2 r0 r1 knee_rot,
    # both normalised
    r0 = quat.from_axis_angle_scalar(bend, ac_ab_1 - ac_ab_0)
    r1 = quat.from_axis_angle_scalar(bend, ba_bc_1 - ba_bc_0)
    r2 = quat.from_axis_angle_scalar(turn, ac_at_0)
    mul = quat.mul_scalar
    return (quat.normalize_scalar(mul(r2, mul(r0, hip_rot))),
            quat.normalize_scalar(mul(r2, mul(r0, mul(r1, knee_rot)))))


class FootLockState:
    """Per foot (left, right): lock flag and position, the lowest height of the animated toe while locked,
    the offset (target minus animated toe) that blends out after an unlock and its velocity, and whether
    the foot was released by the unlock radius during the current contact (it is not locked again before
    that contact ends).

    Mutable and kept in plain floats (the controller advances it in place once per tick, see
    :meth:`update`); the fields read as numpy arrays (``locked`` (2,) bool, ``lock_position`` (2, 3), ...).
    """
    __slots__ = ("_locked", "_released", "_lowest", "_lock", "_off", "_off_v", "_previous", "knees", "_stepping")

    def __init__(self):
        self._locked = [False, False]
        self._released = [False, False]  # unlocked by distance during the current contact
        self._lowest = [0.0, 0.0]
        self._lock = [(0.0, 0.0, 0.0), (0.0, 0.0, 0.0)]
        self._off = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
        self._off_v = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
        self._previous = None  # the last targets, 2 tuples
        self.knees = [KneeLimiter(), KneeLimiter()]
        self._stepping = [False, False]   # blending back after a release by the radius (a step)

    def copy(self) -> "FootLockState":
        s = FootLockState()
        s._locked, s._released, s._lowest = list(self._locked), list(self._released), list(self._lowest)
        s._lock = list(self._lock)
        s._off = [list(o) for o in self._off]
        s._off_v = [list(v) for v in self._off_v]
        s._previous = None if self._previous is None else list(self._previous)
        s.knees = [copy.copy(k) for k in self.knees]
        s._stepping = list(self._stepping)
        return s

    @property
    def locked(self) -> np.ndarray:
        return np.array(self._locked, dtype=bool)

    @property
    def released(self) -> np.ndarray:
        return np.array(self._released, dtype=bool)

    @property
    def lock_position(self) -> np.ndarray:
        return np.array(self._lock, dtype=np.float64)

    @property
    def offset_position(self) -> np.ndarray:
        return np.array(self._off, dtype=np.float64)

    @property
    def offset_velocity(self) -> np.ndarray:
        return np.array(self._off_v, dtype=np.float64)

    @property
    def lowest_animated(self) -> np.ndarray:
        return np.array(self._lowest, dtype=np.float64)

    @property
    def previous_target(self) -> np.ndarray | None:
        return None if self._previous is None else np.array(self._previous, dtype=np.float64)

    def is_locked(self, i: int) -> bool:
        return self._locked[i]

    def update(self, anim, vel, contacts, unlock_radius: float, blend_halflife: float, foot_height: float,
               dt: float, lift_height: float = 0.02, ground_blend_speed: float = 0.1, step_height: float = 0.04,
               root_shift=None, swing_clearance: float = 0.0, lock_speed: float = math.inf,
               lock_follow: float = 0.0, step_halflife: float = 0.0, ground_blend_acceleration: float = 0.0) -> list:
        """:func:`foot_lock_update` in place, on plain floats: ``anim``/``vel`` two 3-tuples each,
        ``contacts`` two bools, ``root_shift`` None or two 3-sequences. Returns the two targets (3-tuples)."""
        locked, released, lowest, lock = self._locked, self._released, self._lowest, self._lock
        off, off_v = self._off, self._off_v
        y0 = float(halflife_to_damping(blend_halflife)) / 2.0
        e0 = math.exp(-y0 * dt)
        if step_halflife > 0.0 and step_halflife != blend_halflife:
            ys = float(halflife_to_damping(step_halflife)) / 2.0
            es = math.exp(-ys * dt)
        else:
            ys, es = y0, e0
        stepping = self._stepping
        targets = []
        for i in range(2):
            a, c = anim[i], contacts[i]
            y, e = (ys, es) if stepping[i] else (y0, e0)
            if not c:
                released[i] = False
            elif released[i] and (off_v[i][1] < 0.0 and off[i][1] < 0.25 * step_height if step_height > 0.0
                                  else abs(off[i][0]) + abs(off[i][1]) + abs(off[i][2]) < 0.01):
                released[i] = False  # the step after a last-resort release has come down: lock again
            if locked[i]:
                lx, ly, lz = lock[i]
                lowest[i] = min(lowest[i], a[1])
                if lock_follow > 0.0 and dt > 0.0:
                    # the lock creeps after the animated toe, slower than skating shows (a smooth speed,
                    # zero at the lock and lock_follow far from it): less to catch up when it lets go
                    gx, gz = a[0] - lx, a[2] - lz
                    g = math.hypot(gx, gz)
                    if g > 1e-9:
                        step = min(g, lock_follow * dt * g / (g + LOCK_FOLLOW_REACH_M))
                        lx, lz = lx + gx * step / g, lz + gz * step / g
                        lock[i] = (lx, ly, lz)
                far = math.hypot(a[0] - lx, a[2] - lz) > unlock_radius
                if far or (not c and a[1] > lowest[i] + lift_height):
                    # release: the offset carries the target from the lock (at rest) back to the animation
                    locked[i] = False
                    released[i] = c
                    off[i] = [lx - a[0], ly - a[1], lz - a[2]]
                    off_v[i] = [-vel[i][0], -vel[i][1], -vel[i][2]]
                    stepping[i] = far
                    if far:
                        y, e = ys, es    # a step: its own (slower) blend, so catching up does not jerk
                    if far and step_height > 0.0:
                        # an upward kick whose critically damped arc peaks at about step_height: x(t) = V t e^-yt
                        off_v[i][1] += step_height * y * math.e
                    targets.append(lock[i])  # this tick the foot is still where it was locked
                    continue
            elif c and not released[i] and math.hypot(vel[i][0], vel[i][2]) <= lock_speed:
                # (a toe shown moving faster than lock_speed, e.g. a transition's blend bringing a contact
                # to a swinging foot, is not frozen at once: that is a pop; it locks once it has slowed)
                # a contact (it began, or a transition brought one): lock where the toe is shown now
                locked[i] = True
                stepping[i] = False
                lowest[i] = a[1]
                lock[i] = (a[0] + off[i][0], max(a[1] + off[i][1], foot_height), a[2] + off[i][2])
                off[i] = [0.0, 0.0, 0.0]
                off_v[i] = [0.0, 0.0, 0.0]
            if locked[i]:
                targets.append(lock[i])
                continue
            if root_shift is not None and a[1] + off[i][1] < lock[i][1] + lift_height:
                # the root was pulled towards the simulation object: a foot near the ground stays put
                shift = root_shift[i]
                cx, cz = off[i][0] - float(shift[0]), off[i][2] - float(shift[2])
                n = math.hypot(cx, cz)
                # at most the unlock radius of it, but never cut to it: an offset already beyond it (a release
                # by the radius, or a standing foot's smaller radius) is left to its blend, not moved at once
                cap = max(unlock_radius, math.hypot(off[i][0], off[i][2]))
                if n > cap:
                    cx, cz = cx * cap / n, cz * cap / n
                off[i][0], off[i][2] = cx, cz
            ox, oy, oz = off[i]
            vx, vy, vz = off_v[i]
            nx, vx = decay_spring_damper_scalar(ox, vx, y, e, dt)
            ny, vy = decay_spring_damper_scalar(oy, vy, y, e, dt)
            nz, vz = decay_spring_damper_scalar(oz, vz, y, e, dt)
            if a[1] + ny < lock[i][1] + lift_height and dt > 0.0:
                # near the ground: the blend may not glide the foot faster than ground_blend_speed
                step = math.hypot(nx - ox, nz - oz)
                cap = ground_blend_speed * dt
                if step > cap:
                    k = cap / step
                    cx, cz = (nx - ox) * k / dt, (nz - oz) * k / dt      # the capped offset velocity
                    if ground_blend_acceleration > 0.0:
                        # reached from the offset's velocity with a bounded acceleration, not at once: the
                        # foot released at rest does not jump to the animation's speed in one tick
                        px, pz = off_v[i][0], off_v[i][2]
                        gx, gz = cx - px, cz - pz
                        g = math.hypot(gx, gz)
                        lim = ground_blend_acceleration * dt
                        if g > lim:
                            cx, cz = px + gx * lim / g, pz + gz * lim / g
                    nx, nz = ox + cx * dt, oz + cz * dt
                    vx, vz = cx, cz
            off[i] = [nx, ny, nz]
            off_v[i] = [vx, vy, vz]
            ty = a[1] + ny
            if swing_clearance > 0.0:
                ty = soft_floor(ty, swing_floor(math.hypot(vel[i][0], vel[i][2]), foot_height, swing_clearance))
            targets.append((a[0] + nx, ty, a[2] + nz))
        self._previous = targets
        return targets


LOCK_FOLLOW_REACH_M = 0.02     # a lock this far behind its animated toe creeps at half the follow speed
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
                     root_shift=None, swing_clearance: float = 0.0, lock_follow: float = 0.0,
                     step_halflife: float = 0.0, ground_blend_acceleration: float = 0.0
                     ) -> tuple[FootLockState, np.ndarray]:
    """Advance the locks one tick. Returns the new state (``state`` is left as it was) and the toe
    targets (2, 3), world space. (The controller calls :meth:`FootLockState.update` in place instead.)

    The rule, per foot:

    * **lock** when the animation's contact begins, where the toe is shown at that moment (so the lock
      does not pop), at least ``foot_height`` above the ground (y = 0);
    * **hold** while the contact lasts, and after it ends until the animated toe has risen
      ``lift_height`` above its lowest point during the lock: the foot leaves the ground when the
      animation lifts it, not earlier. With ``lock_follow`` > 0 the lock creeps horizontally after the
      animated toe at up to that speed (zero at the lock, half of it 2 cm away): the blends and root
      adjustment of the runtime slide an animated foot several times further during a contact than the
      data does, and what the lock holds back must be caught up when it lets go;
    * **last resort**: release when the animated toe is further than ``unlock_radius`` (horizontally)
      from the lock; the foot then steps to the animation (its blend gets an upward kick of about
      ``step_height`` and the halflife ``step_halflife``, when given) instead of sliding there, and locks
      again where it comes down if the contact still holds;
    * **blend back** after a release: the target is the animated toe plus an offset that decays with a
      critically damped spring (``blend_halflife``), starting at the lock with zero velocity. While the
      target is near the ground (less than ``lift_height`` above the last lock) the offset may move
      horizontally at most ``ground_blend_speed``, a limit reached with at most
      ``ground_blend_acceleration`` (when given: a foot released at rest does not take the animation's
      speed in one tick); the rest is absorbed once the foot is in the air (or by the next lock, which
      starts where the foot is shown).
    * **not dragged by the root**: ``root_shift`` (2, 3), when given, is how far this tick's root
      adjustment and clamping moved each animated toe. An unlocked foot near the ground does not follow
      it horizontally (it goes into the offset, up to ``unlock_radius`` of it or the offset it already
      has if that is larger, and is blended out under the same ground speed limit); a locked foot is held
      anyway.
    """
    anim = [tuple(float(v) for v in p) for p in np.asarray(toe_positions, dtype=np.float64)]
    vel = [tuple(float(v) for v in p) for p in np.asarray(toe_velocities, dtype=np.float64)]
    contacts = [bool(c) for c in np.asarray(contacts, dtype=bool)]
    if root_shift is not None:
        root_shift = np.asarray(root_shift, dtype=np.float64).tolist()
    s = state.copy()
    targets = s.update(anim, vel, contacts, unlock_radius, blend_halflife, foot_height, dt, lift_height,
                       ground_blend_speed, step_height, root_shift, swing_clearance, math.inf, lock_follow,
                       step_halflife, ground_blend_acceleration)
    return s, np.array(targets)


def toe_clear_ground(toe_y: float, q, toe_axis_local, toe_length: float, ground_height: float):
    """The toe's global rotation ``q`` bent up (about the horizontal axis across the foot) so the tip of the
    foot, ``toe_length`` along ``toe_axis_local`` from the toe joint (at height ``toe_y``), is not below
    ``ground_height``: a 4-tuple, or None when the toe is left as it is."""
    if toe_length <= 0.0:
        return None
    d = _unit(quat.mul_vec_scalar(q, toe_axis_local))
    if toe_y + toe_length * d[1] >= ground_height:
        return None
    want = _clamp1((ground_height - toe_y) / toe_length)
    angle = math.asin(want) - math.asin(_clamp1(d[1]))
    axis = _cross(d, (0.0, 1.0, 0.0))
    if _norm(axis) < 1e-9:
        return None
    return quat.normalize_scalar(quat.mul_scalar(quat.from_axis_angle_scalar(_unit(axis), angle), q))


def solve_leg(global_pos, global_rot, chain, toe_target, toe_axis_local, toe_length: float,
              ground_height: float | None, min_knee_cos: float = 1.0, soft: float = 0.0,
              knee_limit=None) -> tuple:
    """New global rotations for (hip, knee, foot, toe) of one leg so the toe reaches ``toe_target``, in the
    order of ``chain`` (bone indices). The foot keeps its global rotation (so the toe's offset from the
    ankle is unchanged); the ankle's target is the toe target minus that offset; with a ``ground_height``
    the toe is bent up to keep the tip of the foot above it. One pose as lists of tuples of floats
    (``global_pos[j]`` a 3-tuple, ``global_rot[j]`` a 4-tuple; arrays work too). ``min_knee_cos``, ``soft``:
    the leg's reach (:func:`soft_reach`); ``knee_limit``: :func:`two_bone_ik`'s ``knee``."""
    hip, knee, foot, toe = chain
    tp, fp = global_pos[toe], global_pos[foot]
    # toe_target - (toe - foot)
    ankle_target = (toe_target[0] - (tp[0] - fp[0]), toe_target[1] - (tp[1] - fp[1]),
                    toe_target[2] - (tp[2] - fp[2]))
    hip_rot, knee_rot = two_bone_ik(global_pos[hip], global_pos[knee], fp, ankle_target,
                                    global_rot[hip], global_rot[knee], min_knee_cos=min_knee_cos, soft=soft,
                                    knee=knee_limit)
    toe_rot = global_rot[toe]
    if ground_height is not None:
        bent = toe_clear_ground(toe_target[1], toe_rot, toe_axis_local, toe_length, ground_height)
        if bent is not None:
            toe_rot = bent
    return hip_rot, knee_rot, global_rot[foot], toe_rot


def solve_legs(locks: FootLockState, global_pos, global_rot, leg_chains, targets, toe_axes, toe_length: float,
               foot_height: float, min_knee_cos: float = 1.0, soft: float = 0.0, dt: float = 0.0,
               max_knee_acceleration: float = 0.0) -> list:
    """:func:`solve_leg` for every leg whose toe must move this tick (locked, or free and not yet
    blended back onto the animation): a list of (leg index, new global rotations of its chain). A locked
    toe keeps the tip of the foot above the ground (its lock height minus the foot height). Each knee goes
    through its :class:`KneeLimiter` (``max_knee_acceleration`` rad/s^2, 0: none); a leg left to the
    animation is still solved until its limiter has caught up with the animated knee."""
    solved = []
    straightest = math.acos(min(max(min_knee_cos, -1.0), 1.0))
    for i, leg in enumerate(leg_chains):
        target, toe = targets[i], global_pos[leg[3]]
        is_locked = locks.is_locked(i)
        limiter = locks.knees[i]
        if not is_locked and (abs(target[0] - toe[0]) <= 1e-6 and abs(target[1] - toe[1]) <= 1e-6
                              and abs(target[2] - toe[2]) <= 1e-6):
            hp, kp, fp = global_pos[leg[0]], global_pos[leg[1]], global_pos[leg[2]]
            shown = knee_flexion(_norm(_sub(kp, hp)), _norm(_sub(fp, kp)), _norm(_sub(fp, hp)))
            if (max_knee_acceleration <= 0.0 or limiter.settled(shown)) and shown >= straightest - 1e-6:
                limiter.track(shown, dt)
                continue  # free, fully blended back and the knee where the animation has it: nothing to solve
        ground = target[1] - foot_height if is_locked else None
        knee = (lambda asked, k=limiter: k.step(asked, dt, max_knee_acceleration)) if max_knee_acceleration > 0.0 \
            else None
        solved.append((i, solve_leg(global_pos, global_rot, leg, target, toe_axes[i], toe_length, ground,
                                    min_knee_cos, soft, knee)))
    return solved
