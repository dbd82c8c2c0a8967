"""Inertialization: hide a pose jump by carrying the difference as offsets that decay to zero.

At a transition the offsets become (pose being shown) - (new source pose), per bone, for positions,
velocities, rotations and angular velocities. Every tick the offsets decay with a critically damped
spring (halflife tunable) and the shown pose is source + offsets. The source keeps playing underneath,
so the output stays continuous in position and velocity and converges to the source.

All functions are vectorised over bones; rotations are (w, x, y, z) and rotation offsets are applied
on the left (``shown = offset * source``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lmm import quat
from lmm.springs import decay_spring_damper_exact, decay_spring_damper_exact_quat


@dataclass
class Offsets:
    positions: np.ndarray           # (J, 3)
    velocities: np.ndarray          # (J, 3)
    rotations: np.ndarray           # (J, 4)
    angular_velocities: np.ndarray  # (J, 3)

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


def inertialize_decay(offsets: Offsets, halflife: float, dt: float) -> Offsets:
    """The offsets ``dt`` seconds later."""
    pos, vel = decay_spring_damper_exact(offsets.positions, offsets.velocities, halflife, dt)
    rot, ang = decay_spring_damper_exact_quat(offsets.rotations, offsets.angular_velocities, halflife, dt)
    return Offsets(pos, vel, rot, ang)


def inertialize_apply(offsets: Offsets, positions, velocities, rotations, angular_velocities):
    """The shown pose: source + offsets. Returns (positions, velocities, rotations, angular velocities)."""
    rot = quat.mul(offsets.rotations, rotations)
    return (positions + offsets.positions, velocities + offsets.velocities, quat.normalize(rot),
            offsets.angular_velocities + quat.mul_vec(offsets.rotations, angular_velocities))


def inertialize_update(offsets: Offsets, positions, velocities, rotations, angular_velocities,
                       halflife: float, dt: float):
    """Decay the offsets by ``dt`` and apply them to the new source pose. Returns (offsets, shown pose...)."""
    offsets = inertialize_decay(offsets, halflife, dt)
    return (offsets, *inertialize_apply(offsets, positions, velocities, rotations, angular_velocities))
