"""Inertialization: hide a pose jump by carrying the difference as offsets that decay to zero.

At a transition the offsets become (pose being shown) - (new source pose), per bone, for positions,
velocities, rotations and angular velocities. Every tick the offsets decay with a critically damped
spring (halflife tunable) and the shown pose is source + offsets. The source keeps playing underneath,
so the output stays continuous in position and velocity and converges to the source.

All functions are vectorised over bones; rotations are (w, x, y, z) and rotation offsets are applied
on the left (``shown = offset * source``).

The per-tick functions (:func:`inertialize_decay`, :func:`inertialize_apply`) run once per tick on one
pose of ~20 bones, where a numpy call costs far more than its arithmetic. They perform exactly the float
operations of the spring and quaternion functions of :mod:`lmm.springs` and :mod:`lmm.quat` (same
products, same order of sums: the results are bit for bit identical, tested in
tests/test_inertialize.py) in a few calls on whole arrays: the position and rotation springs run as one
(J, 6) spring, a Hamilton product is 16 signed products summed in four column blocks.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lmm import quat
from lmm.springs import halflife_to_damping


@dataclass
class Offsets:
    positions: np.ndarray           # (J, 3)
    velocities: np.ndarray          # (J, 3)
    rotations: np.ndarray           # (J, 4)
    angular_velocities: np.ndarray  # (J, 3)
    # set by inertialize_decay: the fields as views of its stacked arrays (see there); never compared
    _stack: tuple | None = field(default=None, repr=False, compare=False)

    @classmethod
    def zeros(cls, n_bones: int) -> "Offsets":
        rot = np.zeros((n_bones, 4))
        rot[:, 0] = 1.0
        return cls(np.zeros((n_bones, 3)), np.zeros((n_bones, 3)), rot, np.zeros((n_bones, 3)))

    def copy(self) -> "Offsets":
        return Offsets(self.positions.copy(), self.velocities.copy(), self.rotations.copy(),
                       self.angular_velocities.copy())


def inertialize_transition(shown_positions, shown_velocities, shown_rotations, shown_angular_velocities,
                           dst_positions, dst_velocities, dst_rotations, dst_angular_velocities) -> Offsets:
    """Offsets that make ``dst + offsets`` equal the pose being shown (so the jump is invisible)."""
    rot = quat.abs_(quat.mul_inv(shown_rotations, dst_rotations))
    return Offsets(
        positions=np.asarray(shown_positions - dst_positions, dtype=np.float64),
        velocities=np.asarray(shown_velocities - dst_velocities, dtype=np.float64),
        rotations=rot,
        # shown angular velocity = w_off + R_off w_dst
        angular_velocities=np.asarray(shown_angular_velocities - quat.mul_vec(rot, dst_angular_velocities),
                                      dtype=np.float64),
    )


# Hamilton product a * b as four blocks of signed products, block k holding term k of each component:
# w = aw bw - ax bx - ay by - az bz, x = aw bx + ax bw + ay bz - az by, ... (see lmm.quat.mul); a - p is
# a + (-p) exactly, so summing the blocks left to right is the same arithmetic.
_MUL_A = np.repeat(np.arange(4), 4)
_MUL_B = np.array([0, 1, 2, 3, 1, 0, 3, 2, 2, 3, 0, 1, 3, 2, 1, 0])
_MUL_SIGN = np.array([1.0, 1.0, 1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0, 1.0, -1.0, -1.0, -1.0, 1.0, 1.0])
# cross(a, b) = a[:, L1] * b[:, R1] - a[:, L2] * b[:, R2], both products in one gather each:
# p = a[:, L] * b[:, R] with L = L1 + L2, R = R1 + R2, cross = p[:, :3] - p[:, 3:]
_CROSS_L = np.array([1, 2, 0, 2, 0, 1])
_CROSS_R = np.array([2, 0, 1, 1, 2, 0])
# the same for the vector part of a quaternion (its columns 1..3)
_CROSS_QL = _CROSS_L + 1


def _mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`lmm.quat.mul` of (J, 4) arrays, the same float operations in seven numpy calls."""
    p = a.take(_MUL_A, axis=1)
    p *= _MUL_SIGN
    p *= b.take(_MUL_B, axis=1)
    out = p[:, 0:4] + p[:, 4:8]
    out += p[:, 8:12]
    out += p[:, 12:16]
    return out


def _normalize(q: np.ndarray) -> np.ndarray:
    """:func:`lmm.quat.normalize` of (J, 4), in place (numpy sums a 4-wide last axis left to right)."""
    sq = q * q
    n = sq[:, 0] + sq[:, 1]
    n += sq[:, 2]
    n += sq[:, 3]
    np.sqrt(n, out=n)
    np.maximum(n, 1e-10, out=n)
    q /= n[:, None]
    return q


def _mul_vec(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """:func:`lmm.quat.mul_vec` of (J, 4) and (J, 3): v + w t + u x t with t = 2 (u x v), u = q[:, 1:]."""
    u = q.take(_CROSS_QL, axis=1)       # u's columns for both products of a cross product
    p = v.take(_CROSS_R, axis=1)
    p *= u
    t = p[:, :3] - p[:, 3:]             # u x v
    t *= 2.0
    p = t.take(_CROSS_R, axis=1)
    p *= u
    out = q[:, 0:1] * t
    out += v
    np.subtract(p[:, :3], p[:, 3:], out=t)  # u x t (t is read above, into p, before it is overwritten)
    out += t                            # (v + w t) + (u x t)
    return out


def _norm3(v: np.ndarray) -> np.ndarray:
    """np.linalg.norm(v, axis=-1) of (J, 3): the squares summed left to right."""
    sq = v * v
    n = sq[:, 0] + sq[:, 1]
    n += sq[:, 2]
    return np.sqrt(n, out=n)


def _rotation_log2(q: np.ndarray, out: np.ndarray, eps: float = 1e-8) -> None:
    """``quat.to_scaled_angle_axis(quat.abs_(q))`` of (J, 4) into ``out`` (J, 3)."""
    w = q[:, 0]
    xyz = q[:, 1:]
    length = _norm3(xyz)
    # abs_ negates q where w < 0: |w| here (w = -0.0 gives the same arctan2 unless length is 0, the small
    # branch), and the sign of the vector part folded into the scale ((-s) x == s (-x) exactly)
    c = np.abs(w)
    np.minimum(c, 1.0, out=c)
    angle = np.arctan2(length, c)
    scale = np.ones(len(q))             # 1.0 * xyz == xyz: the small-angle branch (length < eps)
    np.divide(angle, length, out=scale, where=length >= eps)
    # the sign of w, -0.0 counted as positive (abs_ tests w < 0.0); -0.0 + 0.0 == +0.0, others unchanged
    c = w + 0.0
    np.copysign(scale, c, out=scale)
    np.multiply(xyz, scale[:, None], out=out)
    out *= 2.0


def _rotation_exp2(v: np.ndarray, eps: float = 1e-8) -> np.ndarray:
    """``quat.from_scaled_angle_axis(v)`` of (J, 3): a new (J, 4) array."""
    h = v * 0.5
    half = _norm3(h)
    q = np.empty((len(v), 4))
    np.cos(half, out=q[:, 0])
    s = np.sin(half)
    scale = np.ones(len(v))             # the small-angle branch keeps h
    np.divide(s, half, out=scale, where=half >= eps)
    np.multiply(h, scale[:, None], out=q[:, 1:])
    # normalize: the length is cos^2 + sin^2 ~ 1 (or cos(tiny)^2 ~ 1 in the small branch), never under
    # the 1e-10 floor of quat.normalize, so that maximum is left out (NaN stays NaN either way)
    sq = q * q
    n = sq[:, 0] + sq[:, 1]
    n += sq[:, 2]
    n += sq[:, 3]
    np.sqrt(n, out=n)
    q /= n[:, None]
    return q


_SPRING_CONSTANTS: dict = {}


def _spring_constants(halflife: float, dt: float):
    """(y, e) = (damping / 2, exp(-y dt)) as the springs compute them, remembered per (halflife, dt)."""
    key = (halflife, dt)
    c = _SPRING_CONSTANTS.get(key)
    if c is None:
        if len(_SPRING_CONSTANTS) > 64:
            _SPRING_CONSTANTS.clear()
        y = halflife_to_damping(halflife) / 2.0
        c = _SPRING_CONSTANTS[key] = (float(y), float(np.exp(-y * dt)))
    return c


def inertialize_decay(offsets: Offsets, halflife: float, dt: float) -> Offsets:
    """The offsets ``dt`` seconds later: :func:`lmm.springs.decay_spring_damper_exact` on the position
    offsets and :func:`lmm.springs.decay_spring_damper_exact_quat` on the rotation offsets, run as one
    spring on (J, 6) = [position offset, rotation offset's scaled angle axis].

    The result's fields are views of two (J, 6) arrays [position | rotation vector] and [velocity |
    angular velocity]; when the next decay finds them still so (the fields not replaced), it reads the
    velocities as they are and writes the rotation log next to the positions, without gathering."""
    y, e = _spring_constants(halflife, dt)
    n = len(offsets.positions)
    stack = offsets._stack
    pos, vel, ang = offsets.positions, offsets.velocities, offsets.angular_velocities
    if stack is not None and stack[0] is pos and stack[1] is vel and stack[2] is ang:
        x, v = pos.base, vel.base       # the rotation-vector half of x is scratch: overwritten below
    else:
        x = np.empty((n, 6))
        x[:, :3] = pos
        v = np.empty((n, 6))
        v[:, :3] = vel
        v[:, 3:] = ang
    _rotation_log2(offsets.rotations, x[:, 3:])
    j1 = x * y
    j1 += v                             # v + x y
    x_new = j1 * dt
    x_new += x
    x_new *= e                          # e (x + j1 dt)
    v_new = j1 * y
    v_new *= dt
    np.subtract(v, v_new, out=v_new)
    v_new *= e                          # e (v - j1 y dt)
    out = Offsets(x_new[:, :3], v_new[:, :3], _rotation_exp2(x_new[:, 3:]), v_new[:, 3:])
    out._stack = (out.positions, out.velocities, out.angular_velocities)
    return out


def inertialize_apply(offsets: Offsets, positions, velocities, rotations, angular_velocities):
    """The shown pose: source + offsets. Returns (positions, velocities, rotations, angular velocities)."""
    rot = _normalize(_mul(offsets.rotations, rotations))
    return (positions + offsets.positions, velocities + offsets.velocities, rot,
            offsets.angular_velocities + _mul_vec(offsets.rotations, angular_velocities))


def inertialize_update(offsets: Offsets, positions, velocities, rotations, angular_velocities,
                       halflife: float, dt: float):
    """Decay the offsets by ``dt`` and apply them to the new source pose. Returns (offsets, shown pose...)."""
    offsets = inertialize_decay(offsets, halflife, dt)
    return (offsets, *inertialize_apply(offsets, positions, velocities, rotations, angular_velocities))
