"""Quaternion maths, each operation in two forms side by side.

Quaternions have the scalar first: ``q = (w, x, y, z)``. Rotations act on column vectors: ``mul_vec(q, v)``
rotates ``v`` by ``q``.

* The bulk form (``mul``, ``mul_vec``, ...) takes numpy arrays, broadcasts over leading dimensions
  (frames, joints, ...), works in float32 or float64 and never loops in Python over frames or joints.
* The scalar form (``mul_scalar``, ``mul_vec_scalar``, ...) takes one quaternion or 3-vector as a tuple
  of Python floats: the per-tick maths of one character, where a numpy call on a 4-element array costs
  microseconds of overhead for nanoseconds of arithmetic. It performs exactly the float operations of
  its bulk namesake on float64 (same order, same association; numpy sums a short last axis left to
  right), so the two give the same bits (tests/lmm/test_quat.py checks every pair). Where numpy's
  transcendental kernel differs from the C library's in the last bit (``arctan2``), numpy's is called
  on the scalar.
"""
from __future__ import annotations

import math

import numpy as np

_AXES = {"x": 0, "y": 1, "z": 2}
_arctan2 = np.arctan2


def identity(shape=(), dtype=np.float64) -> np.ndarray:
    q = np.zeros(tuple(np.atleast_1d(shape)) + (4,) if shape != () else (4,), dtype=dtype)
    q[..., 0] = 1.0
    return q


def norm_scalar(v) -> float:
    """Length of a 3- or 4-vector (as ``np.linalg.norm(v, axis=-1)``: squares summed left to right)."""
    if len(v) == 3:
        x, y, z = v
        return math.sqrt(x * x + y * y + z * z)
    w, x, y, z = v
    return math.sqrt(w * w + x * x + y * y + z * z)


def normalize(q: np.ndarray, eps: float = 1e-10) -> np.ndarray:
    return q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), eps)


def normalize_scalar(q, eps: float = 1e-10) -> tuple:
    w, x, y, z = q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    n = n if n > eps else eps
    return (w / n, x / n, y / n, z / n)


def conj(q: np.ndarray) -> np.ndarray:
    """Inverse of a unit quaternion."""
    return q * np.array([1.0, -1.0, -1.0, -1.0], dtype=q.dtype)


inv = conj


def conj_scalar(q) -> tuple:
    return (q[0], -q[1], -q[2], -q[3])


def mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b (apply b first, then a)."""
    a, b = np.asarray(a), np.asarray(b)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), dtype=np.result_type(a, b))
    mul_rows(_rows(a), _rows(b), _rows(out))
    return out


def _rows(x: np.ndarray) -> np.ndarray:
    """A view of ``x`` (..., C) with the component axis first, (C, ...): ``_rows(x)[k] is x[..., k]``
    (a transpose costs a fraction of ``np.moveaxis`` on the small arrays of one pose)."""
    n = x.ndim
    return x.transpose((n - 1,) + tuple(range(n - 1))) if n > 1 else x


def mul_rows(a, b, out) -> None:
    """:func:`mul` on quaternions given as four component rows each (``a``, ``b``: sequences of four
    arrays), into the rows of ``out``: the bulk product's one written form."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    out[0] = aw * bw - ax * bx - ay * by - az * bz
    out[1] = aw * bx + ax * bw + ay * bz - az * by
    out[2] = aw * by - ax * bz + ay * bw + az * bx
    out[3] = aw * bz + ax * by - ay * bx + az * bw


# mul_pose: the Hamilton product as four blocks of signed products, block k holding term k of each
# component (w = aw bw - ax bx - ay by - az bz, x = aw bx + ax bw + ay bz - az by, ...: mul_rows' terms in
# its order); a - p is a + (-p) exactly, so summing the blocks left to right is the same arithmetic
_POSE_MUL_A = np.repeat(np.arange(4), 4)
_POSE_MUL_B = np.array([0, 1, 2, 3, 1, 0, 3, 2, 2, 3, 0, 1, 3, 2, 1, 0])
_POSE_MUL_SIGN = np.array([1.0, 1.0, 1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0, 1.0, -1.0, -1.0, -1.0, 1.0, 1.0])
_POSE_MUL_GATHERS: dict = {}


def mul_pose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`mul` of two (J, 4) arrays (one pose's rotations, every tick) in three numpy calls: the signed
    products of each term gathered into a contiguous block, the blocks summed left to right (the same
    bits as :func:`mul` on float64, a quarter of its time on ~20 joints)."""
    n = len(a)
    gathers = _POSE_MUL_GATHERS.get(n)
    if gathers is None:
        rows = (np.arange(n) * 4)[None, :, None]
        gathers = _POSE_MUL_GATHERS[n] = (rows + _POSE_MUL_A.reshape(4, 1, 4), rows + _POSE_MUL_B.reshape(4, 1, 4),
                                          np.broadcast_to(_POSE_MUL_SIGN.reshape(4, 1, 4), (4, n, 4)).copy())
    take_a, take_b, sign = gathers
    p = a.ravel().take(take_a)
    p *= sign
    p *= b.ravel().take(take_b)
    return np.add.reduce(p, 0)          # p[0] + p[1] + p[2] + p[3], left to right


def mul_scalar(a, b) -> tuple:
    """Hamilton product a * b of two 4-tuples."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def inv_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """conj(a) * b."""
    return mul(conj(a), b)


def inv_mul_scalar(a, b) -> tuple:
    """conj(a) * b (a negation is exact: the bits of :func:`inv_mul`)."""
    return mul_scalar(conj_scalar(a), b)


def mul_inv(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a * conj(b)."""
    return mul(a, conj(b))


def mul_inv_scalar(a, b) -> tuple:
    """a * conj(b)."""
    return mul_scalar(a, conj_scalar(b))


def mul_vec(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v (..., 3) by unit quaternions q (..., 4): v + w t + u x t with t = 2 u x v."""
    q, v = np.asarray(q), np.asarray(v)
    out = np.empty(np.broadcast_shapes(q.shape[:-1], v.shape[:-1]) + (3,), dtype=np.result_type(q, v, 2.0))
    mul_vec_rows(_rows(q), _rows(v), _rows(out))
    return out


def mul_vec_rows(q, v, out, plus=None) -> None:
    """:func:`mul_vec` on component rows (``q`` four, ``v`` three), into the rows of ``out``, plus the
    rows of ``plus`` when given (added last, as ``mul_vec(q, v) + plus``): the bulk rotation's one
    written form."""
    w, x, y, z = q
    v0, v1, v2 = v
    t0 = 2.0 * (y * v2 - z * v1)
    t1 = 2.0 * (z * v0 - x * v2)
    t2 = 2.0 * (x * v1 - y * v0)
    r0 = v0 + w * t0 + (y * t2 - z * t1)
    r1 = v1 + w * t1 + (z * t0 - x * t2)
    r2 = v2 + w * t2 + (x * t1 - y * t0)
    if plus is not None:
        r0 += plus[0]
        r1 += plus[1]
        r2 += plus[2]
    out[0], out[1], out[2] = r0, r1, r2


def mul_vec_scalar(q, v, origin=None) -> tuple:
    """Rotate the 3-tuple v by the unit quaternion q. With ``origin`` (a 3-tuple) the result is
    ``origin + v + w t + u x t``, summed in that order: a child's position in single-pose forward
    kinematics (:mod:`lmm.kinematics`)."""
    w, x, y, z = q
    v0, v1, v2 = v
    t0 = 2.0 * (y * v2 - z * v1)
    t1 = 2.0 * (z * v0 - x * v2)
    t2 = 2.0 * (x * v1 - y * v0)
    if origin is not None:
        v0, v1, v2 = origin[0] + v0, origin[1] + v1, origin[2] + v2
    return (v0 + w * t0 + (y * t2 - z * t1), v1 + w * t1 + (z * t0 - x * t2), v2 + w * t2 + (x * t1 - y * t0))


def inv_mul_vec(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v by the inverse of q."""
    return mul_vec(conj(q), v)


def inv_mul_vec_scalar(q, v) -> tuple:
    return mul_vec_scalar(conj_scalar(q), v)


def from_axis_angle(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    axis = np.asarray(axis, dtype=np.float64)
    angle = np.asarray(angle, dtype=np.float64)
    half = angle[..., None] * 0.5
    return np.concatenate([np.cos(half), np.sin(half) * axis], axis=-1)


def from_axis_angle_scalar(axis, angle: float) -> tuple:
    """:func:`from_axis_angle` of one 3-tuple axis and angle (the C library's sin and cos: the bulk form's
    numpy kernels may differ in the last bit)."""
    half = angle * 0.5
    s = math.sin(half)
    return (math.cos(half), s * axis[0], s * axis[1], s * axis[2])


def from_scaled_angle_axis(v: np.ndarray, eps: float = 1e-8) -> np.ndarray:
    """Exponential map: rotation vector (axis * angle, radians) -> quaternion."""
    return exp(v * 0.5, eps)


def from_scaled_angle_axis_scalar(v, eps: float = 1e-8) -> tuple:
    return exp_scalar((v[0] * 0.5, v[1] * 0.5, v[2] * 0.5), eps)


def to_scaled_angle_axis(q: np.ndarray, eps: float = 1e-8) -> np.ndarray:
    """Logarithm map: quaternion -> rotation vector (axis * angle, radians)."""
    return 2.0 * log(q, eps)


def to_scaled_angle_axis_scalar(q, eps: float = 1e-8) -> tuple:
    x, y, z = log_scalar(q, eps)
    return (2.0 * x, 2.0 * y, 2.0 * z)


def angle_axis_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation vector (axis * angle) taking rotations ``b`` to ``a`` the shorter way round."""
    return to_scaled_angle_axis(abs_(mul_inv(a, b)))


def angle_axis_difference_scalar(a, b) -> tuple:
    return to_scaled_angle_axis_scalar(abs_scalar(mul_inv_scalar(a, b)))


def to_scaled_angle_axis_into(q: np.ndarray, out: np.ndarray, eps: float = 1e-8) -> None:
    """``to_scaled_angle_axis(abs_(q))`` of (J, 4) into ``out`` (J, 3): the same values, in the fewest numpy
    calls (inertialization decays one pose's rotation offsets every tick).

    (Whole contiguous arrays and single columns where it can: numpy's fast path; an operation on a 2D
    slice or a broadcast costs it three times more.)"""
    sq = q * q
    length = sq[:, 1] + sq[:, 2]        # the vector part's squares, left to right
    length += sq[:, 3]
    np.sqrt(length, out=length)
    w = q[:, 0]
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
    np.multiply(q[:, 1:], scale[:, None], out=out)
    out *= 2.0


_ONES3 = np.ones(3)


def from_scaled_angle_axis_unnormalized(v: np.ndarray) -> np.ndarray:
    """``from_scaled_angle_axis(v)`` of (J, 3) for one pose per tick: a new (J, 4) array (cos(|v| / 2), sin(|v| / 2) v / |v|),
    in ten numpy calls, without the final normalisation: the length is cos^2 + sin^2 = 1 to rounding, so
    the quotient by it would change the last bit or two at most (within the decay's tested tolerance), and
    whoever applies the offsets normalises the product. |v| is summed by a matrix product (the reference
    halves v first and sums left to right: the same value to a unit in the last place). Near zero
    sin(|v| / 2) / |v| is 1/2 to rounding; at zero the clamped divisor gives 0 times a zero vector."""
    length = np.dot(v * v, _ONES3)
    np.sqrt(length, out=length)
    half = length * 0.5
    q = np.empty((len(v), 4))
    np.cos(half, out=q[:, 0])
    s = np.sin(half)
    np.maximum(length, 1e-300, out=length)
    s /= length
    np.multiply(v, s[:, None], out=q[:, 1:])
    return q


def exp(v: np.ndarray, eps: float = 1e-8) -> np.ndarray:
    half = np.linalg.norm(v, axis=-1, keepdims=True)
    small = half < eps
    safe = np.where(small, 1.0, half)
    w = np.cos(half)
    xyz = np.where(small, v, np.sin(half) / safe * v)
    return normalize(np.concatenate([w, xyz], axis=-1))


def exp_scalar(v, eps: float = 1e-8) -> tuple:
    x, y, z = v
    half = math.sqrt(x * x + y * y + z * z)
    w = math.cos(half)
    if half < eps:
        return normalize_scalar((w, x, y, z))
    s = math.sin(half) / half
    return normalize_scalar((w, s * x, s * y, s * z))


def log(q: np.ndarray, eps: float = 1e-8) -> np.ndarray:
    q = abs_(q)
    length = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    small = length < eps
    safe = np.where(small, 1.0, length)
    halfangle = np.arctan2(length, np.clip(q[..., :1], -1.0, 1.0))
    return np.where(small, q[..., 1:], halfangle / safe * q[..., 1:])


def log_scalar(q, eps: float = 1e-8) -> tuple:
    w, x, y, z = q
    if w < 0.0:  # abs_
        w, x, y, z = -w, -x, -y, -z
    length = math.sqrt(x * x + y * y + z * z)
    if length < eps:
        return (x, y, z)
    w = -1.0 if w < -1.0 else 1.0 if w > 1.0 else w
    s = float(_arctan2(length, w)) / length
    return (s * x, s * y, s * z)


def abs_(q: np.ndarray) -> np.ndarray:
    """The quaternion with non-negative w that represents the same rotation."""
    return np.where(q[..., :1] < 0.0, -q, q)


def abs_scalar(q) -> tuple:
    return (-q[0], -q[1], -q[2], -q[3]) if q[0] < 0.0 else tuple(q)


def from_euler(angles: np.ndarray, order: str) -> np.ndarray:
    """Euler angles (radians) -> quaternion.

    ``order`` names the axes in the order the channels appear in a BVH file,
    e.g. ``"zyx"`` for ``Zrotation Yrotation Xrotation``; ``angles[..., i]`` is the
    angle about axis ``order[i]``. The rotation is R = R(order[0]) R(order[1]) R(order[2])
    (intrinsic, the BVH convention).
    """
    order = order.lower()
    if len(order) != 3 or any(c not in _AXES for c in order):
        raise ValueError(f"bad Euler order {order!r}")
    angles = np.asarray(angles)
    q = None
    for i, c in enumerate(order):
        axis = np.zeros(3)
        axis[_AXES[c]] = 1.0
        qi = from_axis_angle(axis, angles[..., i])
        q = qi if q is None else mul(q, qi)
    return q


def to_euler(q: np.ndarray, order: str) -> np.ndarray:
    """Quaternion -> Euler angles (radians) in ``order`` (see from_euler).

    Works for any of the 6 Tait-Bryan orders through the rotation matrix.
    """
    order = order.lower()
    m = to_matrix(q)
    i, j, k = (_AXES[c] for c in order)
    if len({i, j, k}) != 3:
        raise ValueError(f"only Tait-Bryan orders are supported, got {order!r}")
    # sign of the permutation (i, j, k): +1 for cyclic (xyz, yzx, zxy)
    sign = 1.0 if (j - i) % 3 == 1 else -1.0
    # R = Ri(a) Rj(b) Rk(c): R[i, k] = sign * sin(b)
    sb = np.clip(sign * m[..., i, k], -1.0, 1.0)
    b = np.arcsin(sb)
    a = np.arctan2(-sign * m[..., j, k], m[..., k, k])
    c = np.arctan2(-sign * m[..., i, j], m[..., i, i])
    # gimbal lock: cos(b) ~ 0, put everything into a
    lock = np.abs(sb) > 1.0 - 1e-9
    if np.any(lock):
        a_lock = np.arctan2(sign * m[..., k, j], m[..., j, j])
        a = np.where(lock, a_lock, a)
        c = np.where(lock, 0.0, c)
    return np.stack([a, b, c], axis=-1)


def to_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.stack([
        1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
        2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
        2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
    ], axis=-1)
    return m.reshape(q.shape[:-1] + (3, 3))


def from_matrix(m: np.ndarray) -> np.ndarray:
    """Rotation matrix (..., 3, 3) -> unit quaternion (w >= 0), robust branch per element."""
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    trace = m00 + m11 + m22
    cands = np.stack([
        np.stack([1 + trace, m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], -1),
        np.stack([m[..., 2, 1] - m[..., 1, 2], 1 + m00 - m11 - m22, m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0]], -1),
        np.stack([m[..., 0, 2] - m[..., 2, 0], m[..., 0, 1] + m[..., 1, 0], 1 - m00 + m11 - m22, m[..., 1, 2] + m[..., 2, 1]], -1),
        np.stack([m[..., 1, 0] - m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1], 1 - m00 - m11 + m22], -1),
    ], axis=-2)
    best = np.argmax(np.stack([trace, m00, m11, m22], -1), axis=-1)
    q = np.take_along_axis(cands, best[..., None, None], axis=-2)[..., 0, :]
    return abs_(normalize(q))


def to_xform_xy(q: np.ndarray) -> np.ndarray:
    """The first two columns of the rotation matrix, (..., 3, 2): the 6-D '2-axis' encoding."""
    return to_matrix(q)[..., :2]


def from_xform_xy(xy: np.ndarray) -> np.ndarray:
    """Gram-Schmidt the two columns (..., 3, 2) back to a rotation, then to a quaternion."""
    a = xy[..., 0]
    a = a / np.maximum(np.linalg.norm(a, axis=-1, keepdims=True), 1e-8)
    b = xy[..., 1]
    b = b - np.sum(a * b, axis=-1, keepdims=True) * a
    b = b / np.maximum(np.linalg.norm(b, axis=-1, keepdims=True), 1e-8)
    c = np.cross(a, b)
    return from_matrix(np.stack([a, b, c], axis=-1))


def unroll(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs along ``axis`` (time) so consecutive quaternions lie in the same hemisphere."""
    q = np.moveaxis(np.array(q, copy=True), axis, 0)
    n = q.shape[0]
    if n > 1:
        # per pair of frames, a block at a time on long takes (the same values as in one go)
        dots = np.empty((n - 1,) + q.shape[1:-1], dtype=np.result_type(q.dtype, np.float32))
        for s in frame_blocks(n - 1):
            dots[s] = np.sum(q[s.start + 1:s.stop + 1] * q[s], axis=-1)
        flips = np.cumsum(dots < 0.0, axis=0) % 2
        sign = np.concatenate([np.ones_like(flips[:1]), 1 - 2 * flips], axis=0)
        q = q.astype(np.result_type(q, sign), copy=False)  # the type q * sign has (float32 -> float64)
        for s in frame_blocks(n):
            q[s] *= sign[s][..., None]
    return np.moveaxis(q, 0, axis)


def slerp(a: np.ndarray, b: np.ndarray, t: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """Shortest-path spherical interpolation."""
    t = np.asarray(t)[..., None] if np.ndim(t) else t
    dot = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(dot < 0, -b, b)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_t = np.sin(theta)
    near = sin_t < eps
    safe = np.where(near, 1.0, sin_t)
    wa = np.where(near, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    wb = np.where(near, t, np.sin(t * theta) / safe)
    return normalize(wa * a + wb * b)


def between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Shortest rotation taking direction a onto direction b."""
    c = np.cross(a, b)
    w = np.sqrt(np.sum(a * a, -1) * np.sum(b * b, -1)) + np.sum(a * b, -1)
    return normalize(np.concatenate([w[..., None], c], axis=-1))


def angular_velocity(q0: np.ndarray, q1: np.ndarray, dt: float) -> np.ndarray:
    """World-space angular velocity (rad/s) taking q0 to q1 in dt seconds."""
    return angle_axis_difference(q1, q0) / dt


#: frames per block in bulk per-frame maths (see :func:`frame_blocks`)
FRAME_BLOCK = 1024


def frame_blocks(n: int, block: int = FRAME_BLOCK) -> list[slice]:
    """Slices of ``range(n)``, ``block`` frames each. Maths that is per frame runs block by block on long
    takes: each numpy temporary is then tens of KB that stay in cache, instead of a new array of tens of
    MB per operation (fresh pages to fault in, memory traffic). No operation mixes frames, so the result
    is the same bit for bit (tests/lmm/data/test_database.py)."""
    return [slice(i, min(i + block, n)) for i in range(0, n, block)]


def per_frame_blocks(arrays) -> list[slice] | None:
    """:func:`frame_blocks` for arrays that share a leading frame axis ahead of a joint axis and are
    longer than a block; None otherwise (broadcast or short inputs run in one go)."""
    n = arrays[0].shape[0] if arrays[0].ndim >= 3 else 0
    if n <= FRAME_BLOCK or any(a.ndim < 3 or a.shape[0] != n for a in arrays):
        return None
    return frame_blocks(n)


def joint_major(a: np.ndarray, dtype) -> np.ndarray:
    """A block of frames (B, J, C) as a contiguous (J, C, B) array of ``dtype`` (an exact cast): every
    component of every joint a contiguous row, for :func:`mul_rows` and :func:`mul_vec_rows`."""
    return np.ascontiguousarray(np.asarray(a).transpose(1, 2, 0), dtype=dtype)
