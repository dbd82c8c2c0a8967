"""One quaternion (w, x, y, z) or 3-vector as plain Python floats: the per-tick maths of one character.

A numpy call on a 4-element array costs microseconds of overhead for a few nanoseconds of arithmetic;
these functions do the same arithmetic on tuples of floats. Each one performs exactly the float
operations of its namesake in :mod:`lmm.quat` (same order, same association; numpy sums a short last
axis left to right), so results are bit for bit identical (tested in tests/test_quat_scalar.py). Where
numpy's own transcendental kernel differs from the C library's in the last bit (``arctan2`` here), the
numpy function is called on the scalar.
"""
from __future__ import annotations

import math

import numpy as np

_arctan2 = np.arctan2


def norm(v) -> float:
    """Length of a 3- or 4-vector (as ``np.linalg.norm(v, axis=-1)``)."""
    s = 0.0
    first = True
    for c in v:
        s = c * c if first else s + c * c
        first = False
    return math.sqrt(s)


def normalize(q, eps: float = 1e-10) -> tuple:
    n = norm(q)
    n = n if n > eps else eps
    return tuple(c / n for c in q)


def mul(a, b) -> tuple:
    """Hamilton product a * b."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def conj(q) -> tuple:
    return (q[0], -q[1], -q[2], -q[3])


def mul_inv(a, b) -> tuple:
    """a * conj(b)."""
    return mul(a, conj(b))


def mul_vec(q, v) -> tuple:
    """Rotate the 3-vector v by the unit quaternion q."""
    w, x, y, z = q
    v0, v1, v2 = v
    t0 = 2.0 * (y * v2 - z * v1)
    t1 = 2.0 * (z * v0 - x * v2)
    t2 = 2.0 * (x * v1 - y * v0)
    return (v0 + w * t0 + (y * t2 - z * t1), v1 + w * t1 + (z * t0 - x * t2), v2 + w * t2 + (x * t1 - y * t0))


def inv_mul_vec(q, v) -> tuple:
    return mul_vec(conj(q), v)


def abs_(q) -> tuple:
    """The same rotation with w >= 0."""
    return (-q[0], -q[1], -q[2], -q[3]) if q[0] < 0.0 else tuple(q)


def exp(v, eps: float = 1e-8) -> tuple:
    half = norm(v)
    w = math.cos(half)
    if half < eps:
        return normalize((w, v[0], v[1], v[2]))
    s = math.sin(half) / half
    return normalize((w, s * v[0], s * v[1], s * v[2]))


def log(q, eps: float = 1e-8) -> tuple:
    q = abs_(q)
    length = norm(q[1:])
    if length < eps:
        return (q[1], q[2], q[3])
    w = q[0]
    w = -1.0 if w < -1.0 else 1.0 if w > 1.0 else w
    s = float(_arctan2(length, w)) / length
    return (s * q[1], s * q[2], s * q[3])


def from_scaled_angle_axis(v, eps: float = 1e-8) -> tuple:
    return exp((v[0] * 0.5, v[1] * 0.5, v[2] * 0.5), eps)


def to_scaled_angle_axis(q, eps: float = 1e-8) -> tuple:
    x, y, z = log(q, eps)
    return (2.0 * x, 2.0 * y, 2.0 * z)
