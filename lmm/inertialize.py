"""Inertialization: hide a pose jump by carrying the difference as offsets that decay to zero.

At a transition the offsets become (pose being shown) - (new source pose), per bone, for positions,
velocities, rotations and angular velocities. Every tick the offsets decay with a critically damped
spring (halflife tunable) and the shown pose is source + offsets. The source keeps playing underneath,
so the output stays continuous in position and velocity and converges to the source.

All functions are vectorised over bones; rotations are (w, x, y, z) and rotation offsets are applied
on the left (``shown = offset * source``).

The per-tick functions (:func:`inertialize_decay`, :func:`inertialize_apply`) run once per tick on one
pose of ~20 bones, where a numpy call costs far more than its arithmetic. The decay performs exactly the
float operations of the springs of :mod:`lmm.springs` (tested in tests/lmm/test_inertialize.py) in a few
calls on whole arrays: the position and rotation springs run as one (2, J, 3) spring. Operands are laid
out contiguous and same-shaped where possible (constants as full arrays): numpy runs such an operation
about three times faster than one on a 2D slice, a broadcast or a scalar.
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

    def __deepcopy__(self, memo) -> "Offsets":
        """A copy that the next :func:`inertialize_decay` treats exactly as this one (a session checkpoint
        restores it): fields that are views of the decay's stacked array stay views of a copy of it."""
        stack = self._stack
        if stack is None or not (stack[0] is self.positions and stack[1] is self.velocities
                                 and stack[2] is self.angular_velocities and stack[3] is self.rotations):
            return self.copy()
        t = self.positions.base.copy()
        out = Offsets(t[0, 0], t[1, 0], self.rotations.copy(), t[1, 1])
        out._stack = (out.positions, out.velocities, out.angular_velocities, out.rotations, np.empty_like(stack[4]))
        return out


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


_SPRING_CONSTANTS: dict = {}


def _spring_constants(halflife: float, dt: float, n: int):
    """(y, -y, dt, e) with y = damping / 2 and e = exp(-y dt) as the springs compute them: y and -y as
    (2, n, 3) arrays, dt and e as (2, 2, n, 3) arrays (an operation on same-shaped arrays is numpy's fast
    path, a scalar operand is not), remembered per (halflife, dt, n)."""
    key = (halflife, dt, n)
    c = _SPRING_CONSTANTS.get(key)
    if c is None:
        if len(_SPRING_CONSTANTS) > 64:
            _SPRING_CONSTANTS.clear()
        y = float(halflife_to_damping(halflife) / 2.0)
        e = float(np.exp(-y * dt))
        c = _SPRING_CONSTANTS[key] = (np.full((2, n, 3), y), np.full((2, n, 3), -y),
                                      np.full((2, 2, n, 3), float(dt)), np.full((2, 2, n, 3), e))
    return c


def inertialize_decay(offsets: Offsets, halflife: float, dt: float) -> Offsets:
    """The offsets ``dt`` seconds later: :func:`lmm.springs.decay_spring_damper_exact` on the position
    offsets and :func:`lmm.springs.decay_spring_damper_exact_quat` on the rotation offsets, run as one
    spring on the (2, 2, J, 3) stack [[position offset, rotation offset's scaled angle axis],
    [velocity, angular velocity]].

    With j1 = v + x y the spring is x' = e (x + j1 dt) and v' = e (v - j1 y dt); both halves are made by
    the same three operations on the stack, [j1, -(j1 y)] * dt + [x, v], then * e: the reference's float
    operations (negation is exact), so the positions and velocities are its bits.

    The result's fields are views of that new stack. When the next decay finds them still so (no field
    replaced), it reads the stack as it is, without gathering, and takes the rotation vector the rotations
    were made from instead of their logarithm (the same vector to rounding: a rotation vector differs
    from the logarithm's by at most a few units in the last place, about 1e-16 rad, see
    ``tests/lmm/test_inertialize.py``), unless a component is 1.8 rad or more, where the logarithm is taken
    to keep the offset on the shorter way round."""
    n = len(offsets.positions)
    y, neg_y, dt_, e = _spring_constants(halflife, dt, n)
    stack = offsets._stack
    pos, vel, ang, rot = offsets.positions, offsets.velocities, offsets.angular_velocities, offsets.rotations
    if stack is not None and stack[0] is pos and stack[1] is vel and stack[2] is ang and stack[3] is rot:
        # the rotation vector the rotations were made from: their logarithm again (to rounding) while
        # every component is under 1.8 rad (its length is then under pi: the exponential is the shortest
        # rotation, and abs_ changes nothing); else it is taken, which wraps a vector past pi to the
        # shorter way round as before
        s = pos.base
        scratch = stack[4]
        np.abs(s[0, 1], out=scratch)
        if not scratch.max() < 1.8:     # (NaN: taken too)
            quat.to_scaled_angle_axis_into(rot, s[0, 1])
    else:
        s = np.empty((2, 2, n, 3))
        s[0, 0] = pos
        s[1, 0] = vel
        s[1, 1] = ang
        quat.to_scaled_angle_axis_into(rot, s[0, 1])
    t = np.empty((2, 2, n, 3))
    j1 = t[0]
    np.multiply(s[0], y, out=j1)
    j1 += s[1]                          # v + x y
    np.multiply(j1, neg_y, out=t[1])    # -(j1 y)
    t *= dt_
    t += s
    t *= e                              # [e (x + j1 dt), e (v - j1 y dt)]
    out = Offsets(t[0, 0], t[1, 0], quat.from_scaled_angle_axis_unnormalized(t[0, 1]), t[1, 1])
    out._stack = (out.positions, out.velocities, out.angular_velocities, out.rotations,
                  np.empty((n, 3)) if stack is None else stack[4])
    return out


def inertialize_apply(offsets: Offsets, positions, velocities, rotations, angular_velocities):
    """The shown pose: source + offsets. Returns (positions, velocities, rotations, angular velocities)."""
    pos, rot = inertialize_apply_pose(offsets, positions, rotations)
    vel, ang = _apply_velocities(offsets, velocities, angular_velocities)
    return pos, vel, rot, ang


def _apply_velocities(offsets: Offsets, velocities, angular_velocities):
    """The shown velocities and angular velocities: source + offsets (the offset rotation turns the
    source's angular velocities)."""
    return (velocities + offsets.velocities,
            offsets.angular_velocities + quat.mul_vec(offsets.rotations, angular_velocities))


def inertialize_apply_pose(offsets: Offsets, positions, rotations, normalize: bool = True):
    """The shown pose's positions and rotations alone (those of :func:`inertialize_apply`, the same
    operations): the velocities are needed only at the next transition (:class:`ShownPose`).

    ``normalize=False`` leaves the product unnormalised: for source rotations of unit length to float64
    rounding (the learned controller's decoded ones), since a decay's offsets are too (the exponential
    of a rotation vector), so is their product, to a few units in the last place; rotations read from
    float32 data (the database's) are unit only to about 1e-7 and are normalised."""
    rot = quat.mul_pose(offsets.rotations, rotations)
    return positions + offsets.positions, quat.normalize(rot) if normalize else rot


def inertialize_root_velocities(offsets: Offsets, velocity, angular_velocity) -> tuple[list, tuple]:
    """Bone 0's shown velocity and angular velocity (``velocity``/``angular_velocity``: the source's, 3
    floats each) in plain floats: the values of :func:`inertialize_apply`'s row 0, bit for bit (the scalar
    form of :func:`lmm.quat.mul_vec`)."""
    stack, vel, ang = offsets._stack, offsets.velocities, offsets.angular_velocities
    if stack is not None and stack[1] is vel and stack[2] is ang:
        ov, oa = vel.base[1, :, 0].tolist()   # both rows 0 of the stacked [velocities, angular velocities]
    else:
        ov, oa = vel[0].tolist(), ang[0].tolist()
    r = quat.mul_vec_scalar(offsets.rotations[0].tolist(), angular_velocity)
    return ([velocity[0] + ov[0], velocity[1] + ov[1], velocity[2] + ov[2]],
            (oa[0] + r[0], oa[1] + r[1], oa[2] + r[2]))


class ShownPose:
    """The pose on screen as the 4-tuple (positions, velocities, rotations, angular velocities) that
    :func:`inertialize_apply` returns, with the velocities worked out when first read (by the next
    transition, which most ticks do not have) from the offsets and source pose they came from: the same
    numpy operations on the same arrays (neither is written in place once made), so the same bits.
    ``source``: the source pose (a :class:`lmm.source_pose.SourcePose`), whose velocities are read only then."""

    __slots__ = ("_pos", "_rot", "_offsets", "_vel", "_ang", "_source")

    def __init__(self, positions, rotations, offsets: Offsets, source):
        self._pos, self._rot, self._offsets, self._source = positions, rotations, offsets, source
        self._vel = self._ang = None

    def _velocities(self):
        if self._vel is None:
            src = self._source
            self._vel, self._ang = _apply_velocities(self._offsets, src.velocities, src.angular_velocities)
        return self._vel, self._ang

    def __len__(self):
        return 4

    def __iter__(self):
        vel, ang = self._velocities()
        return iter((self._pos, vel, self._rot, ang))

    def __getitem__(self, i):
        return tuple(self)[i]


def inertialize_update(offsets: Offsets, positions, velocities, rotations, angular_velocities,
                       halflife: float, dt: float):
    """Decay the offsets by ``dt`` and apply them to the new source pose. Returns (offsets, shown pose...)."""
    offsets = inertialize_decay(offsets, halflife, dt)
    return (offsets, *inertialize_apply(offsets, positions, velocities, rotations, angular_velocities))
