"""Controller input derived from a take's root motion: the inverse of the input-to-simulation step.

The controller turns a stick into a desired velocity and facing, and the simulation object follows them
on critically damped springs (:mod:`lmm.trajectory`). Here the take's root path (the database's
simulation bone: the smoothed ground projection of the spine and of the hips' forward axis) is turned back
into sticks and buttons, tick by tick, in closed loop:

* the **desired velocity** that makes the velocity spring follow the take: for a critically damped
  spring ``v'' + 2y v' + y^2 v = y^2 g``, so ``g = v + 2 v'/y + v''/y^2`` of the take's root velocity,
  plus a little feedback on the position and velocity the replayed simulation object has reached, so
  the errors of one tick do not add up over a long take;
* that velocity in the simulation object's frame, divided by the walk or run speeds of
  :class:`lmm.tuning.Tuning` (walk below :data:`WALK_BELOW_M_S`, with hysteresis), is the left stick
  (deadzone undone; clamped to full deflection when the take is faster than the controller may go);
* **facing**: moving forward, the controller faces where it goes; where the take's facing and its
  direction of travel differ (strafing, backpedalling) or it turns on the spot, the strafe button is
  held and the right stick points where the facing spring must aim (the same lead as the velocity).

Each tick is applied through the controller's own functions (deadzone, camera-relative stick, desired
velocity and rotation, spring step), so the replay of the written input log reproduces the simulation
object computed here exactly, and :attr:`DerivedInput.replay_positions` is what a controller will follow.
The take is moved so it starts at the origin facing +Z, as a controller starts after a reset.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lmm import quat
from lmm.controller import InputState
from lmm.errors import InputError
from lmm.springs import halflife_to_damping
from lmm.trajectory import (SimulationState, desired_rotation, desired_velocity, simulation_update, stick_world,
                            yaw_rotation)
from lmm.tuning import Tuning

WALK_BELOW_M_S = 1.2        # walk button held below this desired speed (run above WALK_UNTIL_M_S)
WALK_UNTIL_M_S = 1.45
STAND_BELOW_M_S = 0.05      # no stick below this desired speed
STRAFE_FROM_DEG = 20.0      # facing this far from the direction of travel: strafe (released under ...)
STRAFE_UNTIL_DEG = 10.0
MOVING_M_S = 0.3            # the direction of travel is meaningful above this speed
TURN_ON_SPOT_RAD_S = 0.4    # standing and turning faster than this: strafe to turn
POSITION_GAIN = 1.0         # 1/s: desired velocity per metre of position error
VELOCITY_GAIN = 0.5         # desired velocity per m/s of velocity error
YAW_GAIN = 1.0              # facing lead per radian of facing error


@dataclass
class RootPath:
    """A take's root on the ground: positions (F, 3) in metres and yaw (F,) radians (0 faces +Z,
    unwrapped), at ``fps``; ``frames`` is the file's own frame range it covers."""
    positions: np.ndarray
    yaw: np.ndarray
    fps: float
    frames: tuple[int, int]
    path: str = ""


def take_root_path(anim, manifest, path: str = "", frames: tuple[int, int] | None = None) -> RootPath:
    """The simulation bone of a loaded take (the database's definition, with the manifest's bones,
    unit scale and smoothing), over the file frames ``[a, b)`` (default: all)."""
    from lmm.data.preparation import simulation_bone

    missing = [manifest.bones[k] for k in ("hips", "spine") if manifest.bones[k] not in anim.names]
    if missing:
        raise InputError(f"{path}: no joint named {', '.join(missing)} (the manifest's hips and spine bones)")
    n = anim.n_frames
    a, b = (0, n) if frames is None else frames
    if not (0 <= a < b <= n) or b - a < 2:
        raise InputError(f"{path}: frames {a}:{b} are not a range of at least 2 frames inside the take's 0:{n}")
    g_rot, g_pos = anim.global_transforms()
    g_rot, g_pos = g_rot[a:b], g_pos[a:b] * manifest.unit_scale
    hips, spine = anim.names.index(manifest.bones["hips"]), anim.names.index(manifest.bones["spine"])
    sim_rot, sim_pos = simulation_bone(g_rot, g_pos, spine, hips, manifest.hips_forward_axis, manifest)
    forward = quat.mul_vec(sim_rot, np.array([0.0, 0.0, 1.0]))
    yaw = np.unwrap(np.arctan2(forward[:, 0], forward[:, 2]))
    return RootPath(sim_pos, yaw, 1.0 / anim.frame_time, (a, b), path)


def aligned(root: RootPath) -> RootPath:
    """The path moved and turned so it starts at the origin facing +Z."""
    c, s = math.cos(-root.yaw[0]), math.sin(-root.yaw[0])
    d = root.positions - root.positions[0]
    pos = np.stack([c * d[:, 0] + s * d[:, 2], np.zeros(len(d)), -s * d[:, 0] + c * d[:, 2]], axis=1)
    return RootPath(pos, root.yaw - root.yaw[0], root.fps, root.frames, root.path)


@dataclass
class DerivedInput:
    """The derived input, one row per tick at ``dt``, and the paths it was judged on (all aligned)."""
    dt: float
    inputs: list[InputState]
    reference_positions: np.ndarray     # (n, 3) the take's root at the end of each tick
    reference_yaw: np.ndarray           # (n,)
    replay_positions: np.ndarray        # (n, 3) the simulation object driven by the input
    replay_yaw: np.ndarray              # (n,)
    clamped_ticks: int                  # ticks the take asked for more speed than the controller has

    @property
    def times(self) -> np.ndarray:
        return np.arange(len(self.inputs)) * self.dt

    def path_error(self) -> dict:
        """Root path error of the replay: position (m; mean, 95th percentile, max, final) and facing (deg)."""
        d = np.linalg.norm((self.replay_positions - self.reference_positions)[:, [0, 2]], axis=1)
        yaw = np.degrees(np.abs((self.replay_yaw - self.reference_yaw + np.pi) % (2 * np.pi) - np.pi))
        return {"ticks": len(d), "seconds": len(d) * self.dt,
                "position_mean_m": float(d.mean()), "position_p95_m": float(np.percentile(d, 95)),
                "position_max_m": float(d.max()), "position_final_m": float(d[-1]),
                "yaw_mean_deg": float(yaw.mean()), "yaw_max_deg": float(yaw.max()),
                "clamped_fraction": self.clamped_ticks / max(len(d), 1)}


def _sample(root: RootPath, times: np.ndarray):
    """Position, velocity, acceleration, jerk (n, 3) and yaw, yaw rate, yaw acceleration (n,) of the
    path at ``times`` (linear interpolation of central differences; the path is already smoothed)."""
    t_src = np.arange(len(root.positions)) / root.fps
    p = root.positions
    v = np.gradient(p, t_src, axis=0)
    a = np.gradient(v, t_src, axis=0)
    j = np.gradient(a, t_src, axis=0)
    w = np.gradient(root.yaw, t_src)
    dw = np.gradient(w, t_src)
    t = np.clip(times, 0.0, t_src[-1])
    col = lambda x: np.stack([np.interp(t, t_src, x[:, k]) for k in range(3)], axis=1)  # noqa: E731
    return col(p), col(v), col(a), col(j), np.interp(t, t_src, root.yaw), np.interp(t, t_src, w), \
        np.interp(t, t_src, dw)


def _yaw_of(rotation) -> float:
    f = quat.mul_vec(rotation, np.array([0.0, 0.0, 1.0]))
    return math.atan2(float(f[0]), float(f[2]))


def _stick_for(velocity_world, sim_rotation, walk: bool, tuning: Tuning) -> tuple[float, float, bool]:
    """The left stick (x, y) whose desired velocity (walk or run set) is ``velocity_world``, with the
    deadzone undone; the flag says whether full deflection was not enough."""
    if walk:
        fwd, side, back = tuning.walk_forward_speed_m_s, tuning.walk_sideways_speed_m_s, tuning.walk_backwards_speed_m_s
    else:
        fwd, side, back = tuning.run_forward_speed_m_s, tuning.run_sideways_speed_m_s, tuning.run_backwards_speed_m_s
    local = quat.inv_mul_vec(sim_rotation, np.asarray(velocity_world, np.float64))
    sx = local[0] / side if side > 0 else 0.0
    sz = local[2] / ((fwd if local[2] > 0.0 else back) or 1.0)
    world = quat.mul_vec(sim_rotation, np.array([sx, 0.0, sz]))
    x, y = -float(world[0]), float(world[2])            # camera azimuth 0: world = (-x, 0, y)
    m = math.hypot(x, y)
    clamped = m > 1.0
    if clamped:
        x, y, m = x / m, y / m, 1.0
    if m <= 1e-9:
        return 0.0, 0.0, False
    dz = tuning.stick_deadzone
    raw = dz + m * (1.0 - dz)
    return x * raw / m, y * raw / m, clamped


def _at_rest() -> tuple:
    """The simulation object at the origin facing +Z, at rest, and that desired rotation."""
    zero, facing = (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)
    return SimulationState((zero, zero, zero, facing, zero)), facing


def input_step(sim: SimulationState, desired_rot, inp: InputState, tuning: Tuning, dt: float):
    """Exactly the controller's input step (:meth:`lmm.character.CharacterController.step`): the stick
    through the deadzone and the camera to a desired velocity and rotation, then one spring step.
    Returns the new simulation object and desired rotation."""
    left = stick_world(inp.left_x, inp.left_y, tuning.stick_deadzone, inp.camera_azimuth)
    right = stick_world(inp.right_x, inp.right_y, tuning.stick_deadzone, inp.camera_azimuth)
    des_vel = desired_velocity(left, sim.state[3], inp.walk, tuning)
    desired_rot = desired_rotation(left, right, des_vel, desired_rot, inp.strafe, inp.camera_azimuth)
    sim = SimulationState(simulation_update(*sim.state, des_vel, desired_rot, tuning.simulation_velocity_halflife_s,
                                            tuning.simulation_rotation_halflife_s, dt))
    return sim, desired_rot


def derive_input(root: RootPath, tuning: Tuning | None = None, dt: float = 1.0 / 60.0) -> DerivedInput:
    """Derive the input log for ``root`` (aligned to start at the origin facing +Z), tick by tick."""
    tuning = tuning if tuning is not None else Tuning()
    ref = aligned(root)
    duration = (len(ref.positions) - 1) / ref.fps
    n = max(int(math.floor(duration / dt + 1e-9)), 1)
    # after tick i the simulation object has advanced to (i + 1) dt
    p_r, v_r, a_r, j_r, yaw_r, w_r, dw_r = _sample(ref, (np.arange(n) + 1) * dt)
    y_vel = float(halflife_to_damping(tuning.simulation_velocity_halflife_s)) / 2.0
    y_rot = float(halflife_to_damping(tuning.simulation_rotation_halflife_s)) / 2.0
    sim, des_rot = _at_rest()
    walk = strafe = False
    inputs: list[InputState] = []
    rep_pos = np.zeros((n, 3))
    rep_yaw = np.zeros(n)
    clamped_ticks = 0
    for i in range(n):
        # the velocity the spring must be pulled towards (feed-forward + feedback on where it is)
        goal = v_r[i] + 2.0 * a_r[i] / y_vel + j_r[i] / (y_vel * y_vel)
        goal = goal + POSITION_GAIN * (p_r[i] - sim.position) + VELOCITY_GAIN * (v_r[i] - sim.velocity)
        goal[1] = 0.0
        speed = math.hypot(goal[0], goal[2])
        walk = speed < (WALK_UNTIL_M_S if walk else WALK_BELOW_M_S)
        ref_speed = math.hypot(v_r[i][0], v_r[i][2])
        # facing: strafe where the take's facing and its direction of travel part, or it turns on the spot
        if ref_speed > MOVING_M_S:
            travel = math.atan2(v_r[i][0], v_r[i][2])
            apart = abs((yaw_r[i] - travel + math.pi) % (2 * math.pi) - math.pi)
            strafe = apart > math.radians(STRAFE_UNTIL_DEG if strafe else STRAFE_FROM_DEG)
        else:
            sim_yaw = _yaw_of(sim.rotation)
            off = abs((yaw_r[i] - sim_yaw + math.pi) % (2 * math.pi) - math.pi)
            strafe = abs(w_r[i]) > TURN_ON_SPOT_RAD_S or off > math.radians(10.0)
        if speed < STAND_BELOW_M_S:
            lx = ly = 0.0
            clamped = False
        else:
            lx, ly, clamped = _stick_for(goal, sim.rotation, walk, tuning)
        clamped_ticks += bool(clamped)
        rx = ry = 0.0
        if strafe:
            sim_yaw = _yaw_of(sim.rotation)
            err = (yaw_r[i] - sim_yaw + math.pi) % (2 * math.pi) - math.pi
            aim = sim_yaw + err * (1.0 + YAW_GAIN) + 2.0 * w_r[i] / y_rot + dw_r[i] / (y_rot * y_rot)
            # the right stick points where the facing should aim: world (sin, 0, cos) = (-x, 0, y)
            rx, ry = -math.sin(aim), math.cos(aim)
        inp = InputState(lx, ly, rx, ry, walk, strafe, 0.0)
        sim, des_rot = input_step(sim, des_rot, inp, tuning, dt)
        inputs.append(inp)
        rep_pos[i] = sim.position
        rep_yaw[i] = _yaw_of(sim.rotation)
    return DerivedInput(dt, inputs, p_r, np.asarray(yaw_r), rep_pos, rep_yaw, clamped_ticks)


def replay(inputs, tuning: Tuning | None = None, dt: float = 1.0 / 60.0) -> tuple[np.ndarray, np.ndarray]:
    """The simulation object driven by ``inputs`` (an :class:`InputState` per tick): positions (n, 3)
    and yaw (n,), with the controller's input step and springs."""
    tuning = tuning if tuning is not None else Tuning()
    sim, des_rot = _at_rest()
    pos, yaw = [], []
    for inp in inputs:
        sim, des_rot = input_step(sim, des_rot, inp, tuning, dt)
        pos.append(sim.position.copy())
        yaw.append(_yaw_of(sim.rotation))
    return np.array(pos), np.array(yaw)


def write_input_csv(derived: DerivedInput, path) -> None:
    """The derived input as an input log (one row per change; replayed with ``run --input``)."""
    from lmm.data.inputs import InputCsvWriter

    writer = InputCsvWriter(path, flush_interval_s=1e9)
    try:
        for t, inp in zip(derived.times, derived.inputs):
            writer.write(float(t), inp)
    finally:
        writer.close()


__all__ = ["RootPath", "DerivedInput", "take_root_path", "aligned", "derive_input", "replay",
           "write_input_csv", "yaw_rotation"]
