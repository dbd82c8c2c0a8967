"""Critically damped springs and dampers, solved exactly (no integration error for any dt).

Every function is a pure function of arrays: states broadcast over leading dimensions (bones,
trajectory points, ...), and ``dt`` may itself be an array (e.g. several prediction horizons at once).
Quaternions are (w, x, y, z); angular velocities are rotation vectors per second (rad/s).

The spring parameter used throughout is the *halflife*: the time (s) in which the distance to the
goal halves. A halflife of 0 snaps to the goal (the tiny epsilon keeps the maths finite).
"""
from __future__ import annotations

import numpy as np

from lmm import quat
from lmm import quat_scalar as qs

LN2 = float(np.log(2.0))
EPS = 1e-5


def halflife_to_damping(halflife, eps: float = EPS):
    """Damping coefficient (1/s) of a critically damped spring with the given halflife (s)."""
    return (4.0 * LN2) / (np.asarray(halflife, dtype=np.float64) + eps)


def damping_to_halflife(damping, eps: float = EPS):
    return (4.0 * LN2) / (np.asarray(damping, dtype=np.float64) + eps)


def damper_exact(x, goal, halflife, dt, eps: float = EPS):
    """Exponential approach of ``x`` to ``goal``: the distance halves every ``halflife`` seconds."""
    t = 1.0 - np.exp(-LN2 * np.asarray(dt) / (np.asarray(halflife) + eps))
    return x + (goal - x) * t


def damper_exact_quat(q, goal, halflife, dt, eps: float = EPS):
    """The rotation analogue of :func:`damper_exact` (shortest path)."""
    t = 1.0 - np.exp(-LN2 * np.asarray(dt) / (np.asarray(halflife) + eps))
    return quat.slerp(q, goal, t)


def simple_spring_damper_exact(x, v, goal, halflife, dt, eps: float = EPS):
    """Critically damped spring of ``x`` (velocity ``v``) towards a fixed ``goal``. Returns (x, v).

    x(t) = goal + e^{-y t} (j0 + j1 t), with y = damping / 2, j0 = x0 - goal, j1 = v0 + j0 y.
    """
    y = halflife_to_damping(halflife, eps) / 2.0
    dt = np.asarray(dt)
    j0 = x - goal
    j1 = v + j0 * y
    e = np.exp(-y * dt)
    return e * (j0 + j1 * dt) + goal, e * (v - j1 * y * dt)


def decay_spring_damper_exact(x, v, halflife, dt, eps: float = EPS):
    """Critically damped spring towards zero (used to fade inertialization offsets). Returns (x, v)."""
    y = halflife_to_damping(halflife, eps) / 2.0
    dt = np.asarray(dt)
    j1 = v + x * y
    e = np.exp(-y * dt)
    return e * (x + j1 * dt), e * (v - j1 * y * dt)


def simple_spring_damper_exact_quat(q, w, goal, halflife, dt, eps: float = EPS):
    """Critically damped rotation spring. ``q`` rotation, ``w`` world angular velocity (rad/s). Returns (q, w).

    The spring runs on the rotation vector of q * goal^-1, so it takes the shortest way round.
    """
    if np.ndim(q) == 1 and np.ndim(w) == 1 and np.ndim(goal) == 1 and np.ndim(halflife) == 0 and np.ndim(dt) <= 1:
        return _spring_damper_exact_quat_one(q, w, goal, halflife, dt, eps)
    return _spring_damper_exact_quat_arrays(q, w, goal, halflife, dt, eps)


def _spring_damper_exact_quat_arrays(q, w, goal, halflife, dt, eps: float = EPS):
    y = halflife_to_damping(halflife, eps) / 2.0
    dt = np.asarray(dt)
    j0 = quat.to_scaled_angle_axis(quat.abs_(quat.mul_inv(q, goal)))
    j1 = w + j0 * y
    e = np.exp(-y * dt)[..., None] if np.ndim(dt) else np.exp(-y * dt)
    dt_ = dt[..., None] if np.ndim(dt) else dt
    q_new = quat.mul(quat.from_scaled_angle_axis(e * (j0 + j1 * dt_)), goal)
    return q_new, e * (w - j1 * y * dt_)


def _spring_damper_exact_quat_one(q, w, goal, halflife, dt, eps: float = EPS):
    """:func:`simple_spring_damper_exact_quat` for one rotation (and a scalar ``dt`` or a few horizons) in
    plain floats: the same float operations (bit for bit, tested), without numpy's per-call overhead on
    4-element arrays. ``np.exp`` stays numpy's (its kernel differs from ``math.exp`` in the last bit)."""
    y = float(halflife_to_damping(halflife, eps)) / 2.0
    goal_t = tuple(np.asarray(goal, dtype=np.float64).tolist())
    w_t = np.asarray(w, dtype=np.float64).tolist()
    j0 = qs.to_scaled_angle_axis(qs.abs_(qs.mul_inv(np.asarray(q, dtype=np.float64).tolist(), goal_t)))
    j1 = [wi + j * y for wi, j in zip(w_t, j0)]
    dts = np.asarray(dt, dtype=np.float64)
    es = np.exp(-y * dts)
    if dts.ndim == 0:
        e, d = float(es), float(dts)
        q_new = qs.mul(qs.from_scaled_angle_axis([e * (a + b * d) for a, b in zip(j0, j1)]), goal_t)
        return np.array(q_new), np.array([e * (wi - b * y * d) for wi, b in zip(w_t, j1)])
    q_out = np.empty(dts.shape + (4,))
    w_out = np.empty(dts.shape + (3,))
    for i, (e, d) in enumerate(zip(es.tolist(), dts.tolist())):
        q_out[i] = qs.mul(qs.from_scaled_angle_axis([e * (a + b * d) for a, b in zip(j0, j1)]), goal_t)
        w_out[i] = [e * (wi - b * y * d) for wi, b in zip(w_t, j1)]
    return q_out, w_out


def decay_spring_damper_exact_quat(q, w, halflife, dt, eps: float = EPS):
    """Critically damped decay of a rotation offset ``q`` (and its angular velocity) towards identity."""
    y = halflife_to_damping(halflife, eps) / 2.0
    j0 = quat.to_scaled_angle_axis(quat.abs_(q))
    j1 = w + j0 * y
    e = np.exp(-y * dt)
    return quat.from_scaled_angle_axis(e * (j0 + j1 * dt)), e * (w - j1 * y * dt)


def spring_character_update(x, v, a, v_goal, halflife, dt, eps: float = EPS):
    """A position driven by a critically damped spring on its *velocity*. Returns (x, v, a).

    v(t) = v_goal + e^{-y t} (j0 + j1 t) with j0 = v0 - v_goal, j1 = a0 + j0 y; x(t) is its exact
    integral. ``dt`` may be an array of horizons (then x, v, a gain a trailing horizon axis before the
    vector axis), which is how trajectories are predicted in one call.
    """
    y = halflife_to_damping(halflife, eps) / 2.0
    dt = np.asarray(dt, dtype=np.float64)
    if dt.ndim:
        dt = dt[..., None]
    j0 = v - v_goal
    j1 = a + j0 * y
    e = np.exp(-y * dt)
    x_new = (e * ((-j1) / (y * y) + (-j0 - j1 * dt) / y)
             + j1 / (y * y) + j0 / y + v_goal * dt + x)
    v_new = e * (j0 + j1 * dt) + v_goal
    a_new = e * (a - j1 * y * dt)
    return x_new, v_new, a_new


def spring_rotation_update(q, w, q_goal, halflife, dt, eps: float = EPS):
    """Rotation and angular velocity of a spring towards a fixed goal rotation; ``dt`` may be an array."""
    return simple_spring_damper_exact_quat(q, w, q_goal, halflife, dt, eps)
