"""From sticks to a desired motion, the simulation object that follows it, and its predicted future.

Conventions: Y is up; a rotation's forward axis is +Z. The camera's azimuth is its rotation about +Y
(0: the camera looks along +Z). A stick pushed up means "away from the camera" and right means
"to the camera's right", so for azimuth ``a`` the world direction of stick (x, y) is
``R_y(a) (-x, 0, y)``.

The simulation object is a point with a facing, moved by two critically damped springs: one on its
velocity (towards the desired velocity) and one on its rotation (towards the desired rotation). Its
future is predicted with the same closed-form springs, holding the desired velocity and rotation.

One character per tick: vectors and quaternions are tuples of Python floats (the scalar forms of
:mod:`lmm.quat`), a fraction of the cost of numpy calls on 2-, 3- and 4-element arrays; the tests check
each function against a few lines of numpy (tests/lmm/test_trajectory.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lmm import quat
from lmm.springs import spring_character_update, spring_rotation_update

def trajectory_offsets(features) -> np.ndarray:
    """Every future frame offset the feature layout's trajectory channels use (sorted, unique)."""
    offs = sorted({o for ch in features.layout if ch.kind.startswith("trajectory") for o in ch.offsets})
    return np.asarray(offs, dtype=np.int64)


_hypot = np.hypot        # numpy's hypot and arctan2 differ from the C library's in the last bit
_arctan2 = np.arctan2


def yaw_rotation(angle: float) -> tuple:
    """Rotation about +Y by ``angle`` radians (the zero components included: ``sin * 0.0`` keeps its sign)."""
    return quat.from_axis_angle_scalar((0.0, 1.0, 0.0), angle)


def stick_world(x: float, y: float, deadzone: float, camera_azimuth: float) -> tuple:
    """A stick (x, y) as a world ground-plane vector (3,): a radial deadzone (zero inside, rescaled outside
    so full deflection stays 1), then turned by the camera's azimuth."""
    if x == 0.0 and y == 0.0:  # hypot(0, 0) = 0 <= deadzone: skip the call
        sx = sy = 0.0
    else:
        mag = float(_hypot(x, y))
        if mag <= deadzone or mag <= 0.0:
            sx = sy = 0.0
        else:
            k = min((mag - deadzone) / max(1.0 - deadzone, 1e-6), 1.0) / mag
            sx, sy = x * k, y * k
    return quat.mul_vec_scalar(yaw_rotation(camera_azimuth), (-sx, 0.0, sy))


def desired_velocity(stick_world, simulation_rotation, walk: bool, tuning) -> tuple:
    """World velocity (3,) asked for by the stick: the stick in the simulation object's frame, scaled per
    axis by the forward, sideways and backwards speeds of the walk or run set (sidestepping and
    backpedalling are slower)."""
    if walk:
        fwd, side, back = tuning.walk_forward_speed_m_s, tuning.walk_sideways_speed_m_s, tuning.walk_backwards_speed_m_s
    else:
        fwd, side, back = tuning.run_forward_speed_m_s, tuning.run_sideways_speed_m_s, tuning.run_backwards_speed_m_s
    lx, _, lz = quat.inv_mul_vec_scalar(simulation_rotation, stick_world)
    return quat.mul_vec_scalar(simulation_rotation, (lx * side, 0.0, lz * (fwd if lz > 0.0 else back)))


def desired_rotation(stick_world, right_stick_world, velocity, current_rotation, strafe: bool,
                     camera_azimuth: float) -> tuple:
    """The facing asked for. Strafing faces the right stick's direction when it is pushed, else the
    camera's forward direction; otherwise the character faces where it is asked to go, and keeps its
    facing when asked to stand."""
    if strafe:
        if quat.norm_scalar(right_stick_world) > 1e-5:
            return yaw_rotation(float(_arctan2(right_stick_world[0], right_stick_world[2])))
        return yaw_rotation(camera_azimuth)
    if quat.norm_scalar(velocity) > 1e-5:
        return yaw_rotation(float(_arctan2(velocity[0], velocity[2])))
    return tuple(current_rotation)


class StickWorld:
    """:func:`stick_world` remembering its last answer: a stick rests or is held still on most
    ticks. A repeat is recognised only for the same floats with the same signs of zero (``-0.0 == 0.0``,
    but a stick's or the azimuth's sign of zero can reach the answer's zeros)."""
    __slots__ = ("_key", "_signs", "_value")

    def __init__(self):
        self._key = self._signs = self._value = None

    def __call__(self, x: float, y: float, deadzone: float, camera_azimuth: float) -> tuple:
        key = (x, y, deadzone, camera_azimuth)
        copysign = math.copysign
        if key == self._key:
            signs = (copysign(1.0, x), copysign(1.0, y), copysign(1.0, camera_azimuth))
            if signs == self._signs:
                return self._value
        else:
            signs = (copysign(1.0, x), copysign(1.0, y), copysign(1.0, camera_azimuth))
        value = stick_world(x, y, deadzone, camera_azimuth)
        self._key, self._signs, self._value = key, signs, value
        return value


class SharpInputChange:
    """Whether a sharp change of the desired motion just ended: true on the tick the desired velocity's (or
    rotation's) rate of change falls back under the threshold after exceeding it, when the new trajectory
    is known (the controller then forces a search)."""
    __slots__ = ("velocity_high", "rotation_high")

    def __init__(self):
        self.velocity_high = self.rotation_high = False

    def __call__(self, des_vel, des_rot, prev_vel, prev_rot, threshold: float, dt: float) -> bool:
        """``des_*``/``prev_*``: this tick's and the last tick's desired velocity (3 floats) and rotation
        (4 floats)."""
        if dt <= 0:
            return False
        d0, d1, d2 = des_vel[0] - prev_vel[0], des_vel[1] - prev_vel[1], des_vel[2] - prev_vel[2]
        vel_rate = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) / dt
        if des_rot == prev_rot and threshold * dt > 1e-12:
            # unchanged: q * conj(q)'s vector part is zero up to a rounding or two of its products (under
            # 1e-15), so its rate stays under the threshold; skip the logarithm
            rot_rate = 0.0
        else:
            rot_rate = quat.norm_scalar(quat.angle_axis_difference_scalar(des_rot, prev_rot)) / dt
        forced = False
        if vel_rate > threshold:
            self.velocity_high = True
        elif self.velocity_high:
            self.velocity_high = False
            forced = True
        if rot_rate > threshold:
            self.rotation_high = True
        elif self.rotation_high:
            self.rotation_high = False
            forced = True
        return forced


class SimulationState:
    """The simulation object as one tuple of float tuples ``state`` = (position, velocity, acceleration,
    rotation, angular_velocity), what the per-tick code reads and writes; :class:`SimulationState`'s
    array fields are built when read (a new array on every read)."""
    __slots__ = ("state",)

    def __init__(self, state: tuple):
        self.state = state

    position = property(lambda self: np.array(self.state[0]))
    velocity = property(lambda self: np.array(self.state[1]))
    acceleration = property(lambda self: np.array(self.state[2]))
    rotation = property(lambda self: np.array(self.state[3]))
    angular_velocity = property(lambda self: np.array(self.state[4]))

    def copy(self) -> "SimulationState":
        return SimulationState(self.state)  # tuples are never written


def simulation_update(position, velocity, acceleration, rotation, angular_velocity, velocity_goal,
                      rotation_goal, velocity_halflife: float, rotation_halflife: float, dt: float):
    """One exact spring step of the simulation object: (position, velocity, acceleration, rotation,
    angular_velocity), the rotation renormalised."""
    (pos, vel, acc), = spring_character_update(position, velocity, acceleration, velocity_goal,
                                               velocity_halflife, (dt,))
    (rot, ang), = spring_rotation_update(rotation, angular_velocity, rotation_goal, rotation_halflife, (dt,),
                                         normalize=True)
    return pos, vel, acc, rot, ang


def trajectory_predict(position, velocity, acceleration, rotation, angular_velocity, velocity_goal,
                       rotation_goal, velocity_halflife: float, rotation_halflife: float,
                       times: tuple) -> tuple[list, list]:
    """Positions and rotations (lists of tuples) of the simulation object ``times`` seconds ahead, holding
    the current desired velocity and rotation."""
    positions = spring_character_update(position, velocity, acceleration, velocity_goal, velocity_halflife, times,
                                        positions_only=True)
    turns = spring_rotation_update(rotation, angular_velocity, rotation_goal, rotation_halflife, times,
                                   normalize=True, rotations_only=True)
    return positions, turns


def trajectory_in_root_space(positions, rotations, root_position, root_rotation) -> tuple[list, list]:
    """Trajectory points and facing directions (lists of 3-tuples) in the space of a root (ground-plane
    features)."""
    inverse = quat.conj_scalar(root_rotation)
    rx, ry, rz = root_position
    local_pos = [quat.mul_vec_scalar(inverse, (px - rx, py - ry, pz - rz)) for px, py, pz in positions]
    forward = (0.0, 0.0, 1.0)  # the facing: the rotation's +Z
    local_dir = [quat.mul_vec_scalar(inverse, quat.mul_vec_scalar(q, forward)) for q in rotations]
    return local_pos, local_dir
