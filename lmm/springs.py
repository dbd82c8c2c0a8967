"""Critically damped springs and dampers, solved exactly (no integration error for any dt).

Every function is a pure function of arrays: states broadcast over leading dimensions (bones,
trajectory points, ...), and ``dt`` may itself be an array (e.g. several prediction horizons at once).
Quaternions are (w, x, y, z); angular velocities are rotation vectors per second (rad/s).

The spring parameter used throughout is the *halflife*: the time (s) in which the distance to the
goal halves. A halflife of 0 snaps to the goal (the tiny epsilon keeps the maths finite).
"""
from __future__ import annotations

import functools

import numpy as np

from lmm import quat

LN2 = float(np.log(2.0))
EPS = 1e-5


def halflife_to_damping(halflife, eps: float = EPS):
    """Damping coefficient (1/s) of a critically damped spring with the given halflife (s)."""
    return (4.0 * LN2) / (np.asarray(halflife, dtype=np.float64) + eps)


def damping_to_halflife(damping, eps: float = EPS):
    """The inverse of :func:`halflife_to_damping`: the same relation (4 ln 2 = halflife * damping)."""
    return halflife_to_damping(damping, eps)


def damper_factor(halflife, dt, eps: float = EPS):
    """The fraction of the way to its goal a damper covers in ``dt``: 1 - exp(-ln2 dt / halflife)."""
    return 1.0 - np.exp(-LN2 * np.asarray(dt) / (np.asarray(halflife) + eps))


def damper_exact(x, goal, halflife, dt, eps: float = EPS):
    """Exponential approach of ``x`` to ``goal``: the distance halves every ``halflife`` seconds."""
    return x + (goal - x) * damper_factor(halflife, dt, eps)


def damper_exact_quat(q, goal, halflife, dt, eps: float = EPS):
    """The rotation analogue of :func:`damper_exact` (shortest path)."""
    return quat.slerp(q, goal, damper_factor(halflife, dt, eps))


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
    """:func:`simple_spring_damper_exact_quat` for one rotation (and a scalar ``dt`` or a few horizons):
    :func:`spring_rotation_update` with numpy arrays in and out."""
    dts = np.asarray(dt, dtype=np.float64)
    out = spring_rotation_update(tuple(np.asarray(q, dtype=np.float64).tolist()),
                                 np.asarray(w, dtype=np.float64).tolist(),
                                 tuple(np.asarray(goal, dtype=np.float64).tolist()), halflife,
                                 tuple(dts.ravel().tolist()), eps)
    if dts.ndim == 0:
        return np.array(out[0][0]), np.array(out[0][1])
    return (np.array([q for q, _ in out]).reshape(dts.shape + (4,)),
            np.array([w for _, w in out]).reshape(dts.shape + (3,)))


def decay_spring_damper_scalar(x: float, v: float, y: float, e: float, dt: float) -> tuple[float, float]:
    """:func:`decay_spring_damper_exact` of one float, given ``y`` (damping / 2) and ``e = exp(-y dt)`` as the
    caller computed them once for several components."""
    j1 = v + x * y
    return e * (x + j1 * dt), e * (v - j1 * y * dt)


def decay_spring_damper_exact_quat(q, w, halflife, dt, eps: float = EPS):
    """Critically damped decay of a rotation offset ``q`` (and its angular velocity) towards identity."""
    y = halflife_to_damping(halflife, eps) / 2.0
    j0 = quat.to_scaled_angle_axis(quat.abs_(q))
    j1 = w + j0 * y
    e = np.exp(-y * dt)
    return quat.from_scaled_angle_axis(e * (j0 + j1 * dt)), e * (w - j1 * y * dt)


# ------------------------------------------------------------------------------------------------------
# The simulation object's springs, one character per tick in plain Python floats (no numpy per-call
# overhead on 3- and 4-element arrays; tests/lmm/test_trajectory.py checks them against the closed forms
# written in numpy). Vectors are tuples; ``dts`` is a tuple of horizons (one tick: ``(dt,)``).
# ------------------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=256)
def decay_factors(y: float, dts: tuple) -> tuple:
    """``exp(-y * dt)`` for each ``dt`` with numpy's exp (the C library's differs in the last bit).
    Memoised: the halflife and the horizons change only when the tuning or the frame rate does."""
    return tuple(np.exp(-y * np.asarray(dts, dtype=np.float64)).tolist())


def spring_character_update(x, v, a, v_goal, halflife: float, dts: tuple, eps: float = EPS,
                            positions_only: bool = False) -> list:
    """A position driven by a critically damped spring on its *velocity*: ``[(x, v, a), ...]``, one per
    horizon in ``dts`` (only the ``x`` when ``positions_only``), which is how a trajectory is predicted.

    v(t) = v_goal + e^{-y t} (j0 + j1 t) with j0 = v0 - v_goal, j1 = a0 + j0 y; x(t) is its exact integral.
    Written out per component."""
    y = float(halflife_to_damping(halflife, eps) / 2.0)
    yy = y * y
    x0, x1, x2 = x
    a0, a1, a2 = a
    g0, g1, g2 = v_goal
    c0, c1, c2 = v[0] - g0, v[1] - g1, v[2] - g2               # j0
    b0, b1, b2 = a0 + c0 * y, a1 + c1 * y, a2 + c2 * y          # j1
    nb0, nb1, nb2 = (-b0) / yy, (-b1) / yy, (-b2) / yy
    p0, p1, p2 = b0 / yy, b1 / yy, b2 / yy
    q0, q1, q2 = c0 / y, c1 / y, c2 / y
    by0, by1, by2 = b0 * y, b1 * y, b2 * y
    if positions_only:
        return [(e * (nb0 + (-c0 - b0 * dt) / y) + p0 + q0 + g0 * dt + x0,
                 e * (nb1 + (-c1 - b1 * dt) / y) + p1 + q1 + g1 * dt + x1,
                 e * (nb2 + (-c2 - b2 * dt) / y) + p2 + q2 + g2 * dt + x2)
                for e, dt in zip(decay_factors(y, dts), dts)]
    out = []
    for e, dt in zip(decay_factors(y, dts), dts):
        out.append(((e * (nb0 + (-c0 - b0 * dt) / y) + p0 + q0 + g0 * dt + x0,
                     e * (nb1 + (-c1 - b1 * dt) / y) + p1 + q1 + g1 * dt + x1,
                     e * (nb2 + (-c2 - b2 * dt) / y) + p2 + q2 + g2 * dt + x2),
                    (e * (c0 + b0 * dt) + g0, e * (c1 + b1 * dt) + g1, e * (c2 + b2 * dt) + g2),
                    (e * (a0 - by0 * dt), e * (a1 - by1 * dt), e * (a2 - by2 * dt))))
    return out


def spring_rotation_update(q, w, goal, halflife: float, dts: tuple, eps: float = EPS,
                           normalize: bool = False, rotations_only: bool = False) -> list:
    """Rotation and angular velocity of a spring towards a fixed goal rotation (the closed form of
    :func:`simple_spring_damper_exact_quat`, for one rotation): ``[(q, w), ...]``, one per horizon; ``q``
    renormalised (as ``quat.normalize``) only when ``normalize``; only the ``q`` when ``rotations_only``."""
    y = float(halflife_to_damping(halflife, eps) / 2.0)
    j00, j01, j02 = quat.angle_axis_difference_scalar(q, goal)
    w0, w1, w2 = w
    b0, b1, b2 = w0 + j00 * y, w1 + j01 * y, w2 + j02 * y      # j1
    by0, by1, by2 = b0 * y, b1 * y, b2 * y
    out = []
    for e, dt in zip(decay_factors(y, dts), dts):
        r = quat.mul_scalar(quat.from_scaled_angle_axis_scalar((e * (j00 + b0 * dt), e * (j01 + b1 * dt),
                                                                 e * (j02 + b2 * dt))), goal)
        if normalize:
            r = quat.normalize_scalar(r)
        out.append(r if rotations_only else (r, (e * (w0 - by0 * dt), e * (w1 - by1 * dt), e * (w2 - by2 * dt))))
    return out
