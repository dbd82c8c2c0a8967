"""From sticks to a desired motion, the simulation object that follows it, and its predicted future.

Conventions: Y is up; a rotation's forward axis is +Z. The camera's azimuth is its rotation about +Y
(0: the camera looks along +Z). A stick pushed up means "away from the camera" and right means
"to the camera's right", so for azimuth ``a`` the world direction of stick (x, y) is
``R_y(a) (-x, 0, y)``.

The simulation object is a point with a facing, moved by two critically damped springs: one on its
velocity (towards the desired velocity) and one on its rotation (towards the desired rotation). Its
future is predicted with the same closed-form springs, holding the desired velocity and rotation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lmm import quat
from lmm.springs import (spring_character_floats, spring_character_update, spring_rotation_floats,
                         spring_rotation_update)

UP = np.array([0.0, 1.0, 0.0])
FORWARD = np.array([0.0, 0.0, 1.0])


def yaw_rotation(angle) -> np.ndarray:
    """Rotation about +Y by ``angle`` radians."""
    return quat.from_axis_angle(UP, np.asarray(angle, dtype=np.float64))


def facing_rotation(direction) -> np.ndarray:
    """The yaw rotation whose forward (+Z) points along the ground-plane ``direction``."""
    d = np.asarray(direction, dtype=np.float64)
    return yaw_rotation(np.arctan2(d[..., 0], d[..., 2]))


def stick_with_deadzone(x: float, y: float, deadzone: float) -> np.ndarray:
    """Radial deadzone: zero inside, rescaled outside so full deflection stays 1. Returns (2,)."""
    s = np.array([x, y], dtype=np.float64)
    mag = float(np.hypot(s[0], s[1]))
    if mag <= deadzone or mag <= 0.0:
        return np.zeros(2)
    scaled = min((mag - deadzone) / max(1.0 - deadzone, 1e-6), 1.0)
    return s * (scaled / mag)


def stick_to_world(stick: np.ndarray, camera_azimuth: float) -> np.ndarray:
    """Camera-relative stick (2,) -> world ground-plane vector (3,) of the same length."""
    return quat.mul_vec(yaw_rotation(camera_azimuth), np.array([-stick[0], 0.0, stick[1]]))


def desired_velocity(stick_world: np.ndarray, simulation_rotation: np.ndarray, walk: bool, tuning) -> np.ndarray:
    """World velocity (3,) asked for by the stick.

    The stick is expressed in the simulation object's frame and scaled per axis by the forward,
    sideways and backwards speeds of the walk or run set, so sidestepping and backpedalling are slower.
    """
    if walk:
        fwd, side, back = tuning.walk_forward_speed_m_s, tuning.walk_sideways_speed_m_s, tuning.walk_backwards_speed_m_s
    else:
        fwd, side, back = tuning.run_forward_speed_m_s, tuning.run_sideways_speed_m_s, tuning.run_backwards_speed_m_s
    local = quat.inv_mul_vec(simulation_rotation, stick_world)
    local = np.array([local[0] * side, 0.0, local[2] * (fwd if local[2] > 0.0 else back)])
    return quat.mul_vec(simulation_rotation, local)


def desired_rotation(stick_world: np.ndarray, right_stick_world: np.ndarray, velocity: np.ndarray,
                     current_rotation: np.ndarray, strafe: bool, camera_azimuth: float) -> np.ndarray:
    """The facing asked for.

    Strafing faces the right stick's direction when it is pushed, else the camera's forward direction.
    Otherwise the character faces where it is asked to go, and keeps its facing when asked to stand.
    """
    if strafe:
        if np.linalg.norm(right_stick_world) > 1e-5:
            return facing_rotation(right_stick_world)
        return yaw_rotation(camera_azimuth)
    if np.linalg.norm(velocity) > 1e-5:
        return facing_rotation(velocity)
    return np.array(current_rotation, dtype=np.float64)


@dataclass
class SimulationState:
    """The simulation object: where the character should be. World space, float64."""
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    acceleration: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    angular_velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def copy(self) -> "SimulationState":
        return SimulationState(self.position.copy(), self.velocity.copy(), self.acceleration.copy(),
                               self.rotation.copy(), self.angular_velocity.copy())


def simulation_update(state: SimulationState, velocity_goal, rotation_goal, velocity_halflife: float,
                      rotation_halflife: float, dt: float) -> SimulationState:
    """One exact spring step of the simulation object."""
    pos, vel, acc = spring_character_update(state.position, state.velocity, state.acceleration,
                                            velocity_goal, velocity_halflife, dt)
    rot, ang = spring_rotation_update(state.rotation, state.angular_velocity, rotation_goal, rotation_halflife, dt)
    return SimulationState(pos, vel, acc, quat.normalize(rot), ang)


def trajectory_predict(state: SimulationState, velocity_goal, rotation_goal, velocity_halflife: float,
                       rotation_halflife: float, times) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions (T, 3), rotations (T, 4) and velocities (T, 3) of the simulation object ``times`` (T,)
    seconds ahead, holding the current desired velocity and rotation."""
    times = np.asarray(times, dtype=np.float64)
    pos, vel, _ = spring_character_update(state.position, state.velocity, state.acceleration,
                                          velocity_goal, velocity_halflife, times)
    rot, _ = spring_rotation_update(state.rotation, state.angular_velocity, rotation_goal, rotation_halflife, times)
    return pos, quat.normalize(rot), vel


def trajectory_offsets(features) -> np.ndarray:
    """Every future frame offset the feature layout's trajectory channels use (sorted, unique)."""
    offs = sorted({o for ch in features.layout if ch.kind.startswith("trajectory") for o in ch.offsets})
    return np.asarray(offs, dtype=np.int64)


def trajectory_in_root_space(positions, rotations, root_position, root_rotation):
    """Trajectory points and facing directions (T, 3) in the space of a root (ground-plane features)."""
    local_pos = quat.inv_mul_vec(root_rotation, positions - root_position)
    local_dir = quat.inv_mul_vec(root_rotation, quat.mul_vec(rotations, FORWARD))
    return local_pos, local_dir


# ------------------------------------------------------------------------------------------------------
# One character per tick in plain Python floats (vectors and quaternions as tuples): the same float
# operations as the numpy forms above, bit for bit (tested in tests/test_trajectory_floats.py), at a
# fraction of the cost of numpy calls on 2-, 3- and 4-element arrays.
# ------------------------------------------------------------------------------------------------------
_hypot = np.hypot        # numpy's hypot and arctan2 differ from the C library's in the last bit
_arctan2 = np.arctan2


def yaw_rotation_floats(angle: float) -> tuple:
    """:func:`yaw_rotation` as a tuple (the zero components included: ``sin * 0.0`` keeps its sign)."""
    return quat.from_axis_angle_scalar((0.0, 1.0, 0.0), angle)


def stick_world_floats(x: float, y: float, deadzone: float, camera_azimuth: float) -> tuple:
    """``stick_to_world(stick_with_deadzone(x, y, deadzone), camera_azimuth)`` as a tuple (3,)."""
    if x == 0.0 and y == 0.0:  # hypot(0, 0) = 0 <= deadzone: skip the call
        sx = sy = 0.0
    else:
        mag = float(_hypot(x, y))
        if mag <= deadzone or mag <= 0.0:
            sx = sy = 0.0
        else:
            k = min((mag - deadzone) / max(1.0 - deadzone, 1e-6), 1.0) / mag
            sx, sy = x * k, y * k
    return quat.mul_vec_scalar(yaw_rotation_floats(camera_azimuth), (-sx, 0.0, sy))


def desired_velocity_floats(stick_world, simulation_rotation, walk: bool, tuning) -> tuple:
    """:func:`desired_velocity` on tuples."""
    if walk:
        fwd, side, back = tuning.walk_forward_speed_m_s, tuning.walk_sideways_speed_m_s, tuning.walk_backwards_speed_m_s
    else:
        fwd, side, back = tuning.run_forward_speed_m_s, tuning.run_sideways_speed_m_s, tuning.run_backwards_speed_m_s
    lx, _, lz = quat.inv_mul_vec_scalar(simulation_rotation, stick_world)
    return quat.mul_vec_scalar(simulation_rotation, (lx * side, 0.0, lz * (fwd if lz > 0.0 else back)))


def desired_rotation_floats(stick_world, right_stick_world, velocity, current_rotation, strafe: bool,
                            camera_azimuth: float) -> tuple:
    """:func:`desired_rotation` on tuples."""
    if strafe:
        if quat.norm_scalar(right_stick_world) > 1e-5:
            return yaw_rotation_floats(float(_arctan2(right_stick_world[0], right_stick_world[2])))
        return yaw_rotation_floats(camera_azimuth)
    if quat.norm_scalar(velocity) > 1e-5:
        return yaw_rotation_floats(float(_arctan2(velocity[0], velocity[2])))
    return tuple(current_rotation)


class StickWorld:
    """:func:`stick_world_floats` remembering its last answer: a stick rests or is held still on most
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
        value = stick_world_floats(x, y, deadzone, camera_azimuth)
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


class SimulationFloats:
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

    def copy(self) -> SimulationState:
        return SimulationState(*(np.array(x) for x in self.state))


def simulation_update_floats(position, velocity, acceleration, rotation, angular_velocity, velocity_goal,
                             rotation_goal, velocity_halflife: float, rotation_halflife: float, dt: float):
    """:func:`simulation_update` on tuples: (position, velocity, acceleration, rotation, angular_velocity)."""
    (pos, vel, acc), = spring_character_floats(position, velocity, acceleration, velocity_goal,
                                               velocity_halflife, (dt,))
    (rot, ang), = spring_rotation_floats(rotation, angular_velocity, rotation_goal, rotation_halflife, (dt,),
                                         normalize=True)
    return pos, vel, acc, rot, ang


def trajectory_predict_floats(position, velocity, acceleration, rotation, angular_velocity, velocity_goal,
                              rotation_goal, velocity_halflife: float, rotation_halflife: float,
                              times: tuple) -> tuple[list, list]:
    """:func:`trajectory_predict` on tuples: the positions and rotations (lists of tuples), one per time."""
    positions = spring_character_floats(position, velocity, acceleration, velocity_goal, velocity_halflife, times,
                                        positions_only=True)
    turns = spring_rotation_floats(rotation, angular_velocity, rotation_goal, rotation_halflife, times,
                                   normalize=True, rotations_only=True)
    return positions, turns


def trajectory_in_root_space_floats(positions, rotations, root_position, root_rotation) -> tuple[list, list]:
    """:func:`trajectory_in_root_space` on tuples: lists of local positions and facing directions.
    The rotations are the scalar forms of :mod:`lmm.quat` (zero products included), so the bits of the
    numpy form."""
    inverse = quat.conj_scalar(root_rotation)
    rx, ry, rz = root_position
    local_pos = [quat.mul_vec_scalar(inverse, (px - rx, py - ry, pz - rz)) for px, py, pz in positions]
    forward = (0.0, 0.0, 1.0)  # the facing: the rotation's +Z
    local_dir = [quat.mul_vec_scalar(inverse, quat.mul_vec_scalar(q, forward)) for q in rotations]
    return local_pos, local_dir
