"""Decoding a decompressor output vector (:mod:`lmm.nn`'s pose vector) into a :class:`SourcePose`: the two
rotation axes of each bone's 2-axis transform to a quaternion, in a few whole-array numpy calls into
preallocated buffers (:class:`PoseDecoder`), with the bones' velocities worked out only when read (the
learned controller's per-tick decoding computes the other columns and these later)."""
from __future__ import annotations

import functools

import numpy as np

from lmm.nn import pose_vector_slices, pose_vector_tick_columns
from lmm.source_pose import SourcePose


# 4 |q_i|^2 = (+-m00 +-m11 +-m22) + 1: the signs, and the 1 as a fourth column (against a row of ones)
_QUAT_DIAG_SIGNS = np.array([[1.0, 1.0, 1.0, 1.0], [1.0, -1.0, -1.0, 1.0], [-1.0, 1.0, -1.0, 1.0], [-1.0, -1.0, 1.0, 1.0]])
# rows of the scratch matrix (27, n) of :class:`XformToQuat`:
#   0-2 a (the first axis, normalised in place)   3-5 b = (a x b_raw) x a, normalised
#   6-10 c = a x b_raw, cyclic (c0 c1 c2 c0 c1), rows 6-8 normalised   11 unused   12 ones
#   13-19 the first axis cyclic (a0 a1 a2 a0 a1 a2 a0)   20-26 the second axis cyclic (b0 b1 b2 b0 b1 b2 b0)
# so that every cross product term is a slice, the matrix [a b c] is rows 0-8 and its diagonal (a0, b1,
# c2, with the ones) rows 0, 4, 8, 12
XFORM_ROWS = 27
XFORM_A, XFORM_A7, XFORM_B7, XFORM_ONES = slice(0, 3), slice(13, 20), slice(20, 27), 12
# the sums of the squares of each of a, b and c, repeated for each of their rows (rows 0-8 of the scratch)
_GROUP_SUMS = np.kron(np.eye(3), np.ones((3, 3)))
# (m21 - m12, m02 - m20, m10 - m01) = (b2 - c1, c0 - a2, a1 - b0) from rows 0-8
_SIGN_DIFFERENCES = np.zeros((3, 9))
for _row, (_plus, _minus) in enumerate(((5, 7), (6, 2), (1, 3))):
    _SIGN_DIFFERENCES[_row, _plus], _SIGN_DIFFERENCES[_row, _minus] = 1.0, -1.0


def xform_gather_rows(axis_a, axis_b, one, filler) -> np.ndarray:
    """Gather indices (XFORM_ROWS, n) that fill :attr:`XformToQuat.x` from a flat vector: ``axis_a`` and
    ``axis_b`` (3, n) index the two axes' components, ``one`` a slot holding 1.0 and ``filler`` any slot
    (for the rows the conversion computes)."""
    axis_a, axis_b = np.asarray(axis_a), np.asarray(axis_b)
    rows = np.full((XFORM_ROWS, axis_a.shape[1]), filler)
    rows[XFORM_A] = axis_a
    rows[XFORM_A7] = axis_a[[0, 1, 2, 0, 1, 2, 0]]
    rows[XFORM_B7] = axis_b[[0, 1, 2, 0, 1, 2, 0]]
    rows[XFORM_ONES] = one
    return rows


class XformToQuat:
    """2-axis rotations of ``n`` bones, component-major, -> unit quaternions, into preallocated buffers
    with every view made once (a numpy call on a 3 x 23 block costs far more than its arithmetic, so the
    work is about the number of calls: 17 here).

    Fill :attr:`x` (see :func:`xform_gather_rows` for its rows: the two axes, the first also written at
    rows 0-2, both cyclically so the cross products' terms are slices), then :meth:`__call__` writes the
    quaternions to ``out`` (4, n), e.g. the transposed view of a new (n, 4) array.

    The frame is Gram-Schmidt's without its sequence: c = a x b_raw, b = c x a (= |a|^2 times the part of
    b_raw orthogonal to a), then a, b and c normalised together. The quaternion's magnitudes come from the
    matrix diagonal, their signs from the off-diagonal differences, and 0.5 scales the result (the
    magnitudes of an orthonormal frame's quaternion sum to one to rounding: it is not normalised again).
    The same rotations as Gram-Schmidt and :func:`lmm.quat.from_xform_xy` to rounding (typically 1e-16;
    1e-8 bounds a component near zero, whose square root both take: ``tests/lmm/test_nn.py``); a
    degenerate frame (an axis of length zero, parallel axes) gives NaN.
    """

    def __init__(self, n: int):
        self.x = x = np.empty((XFORM_ROWS, n))
        x[XFORM_ONES] = 1.0
        self._q = q = np.empty((4, n))
        t1, t2 = np.empty((5, n)), np.empty((5, n))
        s9, lengths = np.empty((9, n)), np.empty((9, n))
        d = np.empty((3, n))
        zeros, half = np.zeros((4, n)), np.full((4, n), 0.5)
        frame = x[0:9]
        mul, sub, matmul = np.multiply, np.subtract, np.matmul
        # (function, positional arguments) in order; the output is the last positional argument, except
        # for np.maximum (a positional out is deprecated there); every operand contiguous (numpy's fast
        # path) except the diagonal's rows
        self._ops = (
            (mul, (x[14:19], x[22:27], t1)), (mul, (x[15:20], x[21:26], t2)), (sub, (t1, t2, x[6:11])),  # c
            (mul, (x[7:10], x[15:18], t1[:3])), (mul, (x[8:11], x[14:17], t2[:3])),                  # b = c x a
            (sub, (t1[:3], t2[:3], x[3:6])),
            (mul, (frame, frame, s9)),                 # a, b and c normalised together
            (matmul, (_GROUP_SUMS, s9, lengths)), (np.sqrt, (lengths, lengths)), (np.divide, (frame, lengths, frame)),
            (matmul, (_QUAT_DIAG_SIGNS, x[0:13:4], q)),   # 4 |q_i|^2 from the diagonal
            (functools.partial(np.maximum, out=q), (q, zeros)),
            (np.sqrt, (q, q)),                         # 2 |q_i|
            # signs of (m21 - m12, m02 - m20, m10 - m01); + 0.0 makes a -0.0 difference +0.0 (not negative)
            (matmul, (_SIGN_DIFFERENCES, frame, d)), (np.add, (d, zeros[1:], d)), (np.copysign, (q[1:], d, q[1:])),
        )
        self._half = half

    def __call__(self, out: np.ndarray) -> np.ndarray:
        for f, args in self._ops:
            f(*args)
        return np.multiply(self._q, self._half, out=out)


def xform_xy_to_quat(xy: np.ndarray) -> np.ndarray:
    """2-axis rotations (J, 3, 2) -> unit quaternions (J, 4) in few numpy calls.

    Same rotations as :func:`lmm.quat.from_xform_xy` (up to sign and rounding), several times faster
    for one pose (see :class:`XformToQuat`, which the pose decoding keeps and fills with its own gather)."""
    n = xy.shape[0]
    conv = XformToQuat(n)
    flat = np.concatenate([xy[:, :, 0].T.ravel(), xy[:, :, 1].T.ravel(), [1.0]])
    idx = np.arange(3 * n).reshape(3, n)
    flat.take(xform_gather_rows(idx, idx + 3 * n, 6 * n, 6 * n), out=conv.x, mode="clip")
    out = np.empty((n, 4))
    conv(out.T)
    return out


class PoseDecoder:
    """Decompressor output vectors (P,) -> :class:`SourcePose` (float64; bone 0 carries root velocities;
    rotations of unit length to float64 rounding, ``unit_rotations``).

    One gather builds positions, velocities and angular velocities of all bones (bone 0's position is a
    constant zero slot) and one the rotations' axes (bone 0's rotation is decoded from a constant identity
    2-axis matrix, which gives exactly (1, 0, 0, 0)), so a pose costs a cast, two gathers and the rotation
    arithmetic on all bones at once. The returned arrays are new each call (callers keep source poses)."""

    def __init__(self, n_bones: int):
        s = pose_vector_slices(n_bones)
        size = s["contacts"].stop
        zero, one = size, size + 1
        self.n_bones = n_bones
        self._y = np.zeros(size + 2)
        self._y[one] = 1.0
        self._y_head = self._y[:size]
        self._y_contacts = self._y[s["contacts"]]

        def rows(name, shape):
            return np.arange(s[name].start, s[name].stop).reshape(shape)

        j = n_bones - 1
        pva = np.full((3, n_bones, 3), zero)
        pva[0, 1:] = rows("positions", (j, 3))
        pva[1, 0], pva[1, 1:] = rows("root_velocity", 3), rows("velocities", (j, 3))
        pva[2, 0], pva[2, 1:] = rows("root_angular_velocity", 3), rows("angular_velocities", (j, 3))
        self._pva = pva
        xy = rows("rotations", (j, 3, 2))
        axis_a, axis_b = np.full((3, n_bones), zero), np.full((3, n_bones), zero)
        axis_a[0, 0] = axis_b[1, 0] = one              # bone 0: a = (1, 0, 0), b = (0, 1, 0)
        axis_a[:, 1:], axis_b[:, 1:] = xy[:, :, 0].T, xy[:, :, 1].T
        self._axes = xform_gather_rows(axis_a, axis_b, one, zero)
        self._to_quat = XformToQuat(n_bones)

        # the per-tick form (see tick): the tick columns only, in their order, then the two constant slots
        cols = pose_vector_tick_columns(n_bones)
        at = np.full(size + 2, -1)
        at[cols] = np.arange(len(cols))
        at[zero], at[one] = len(cols), len(cols) + 1
        self._t = np.zeros(len(cols) + 2)
        self._t[-1] = 1.0
        self._t_head = self._t[:len(cols)]
        self._t_pos = at[pva[0]]
        self._t_axes = at[self._axes]

        def tick_slice(name):       # an entry of the pose vector, where the tick form holds it
            start = int(at[s[name].start])
            return slice(start, start + s[name].stop - s[name].start)

        self._t_root_slices = (tick_slice("root_velocity"), tick_slice("root_angular_velocity"))
        self._t_contacts = self._t[tick_slice("contacts")]

    def _rotations(self, buf: np.ndarray, axes: np.ndarray) -> np.ndarray:
        """A new (J, 4) array of the rotations whose axes ``axes`` gathers from ``buf``."""
        buf.take(axes, out=self._to_quat.x, mode="clip")
        rot = np.empty((self.n_bones, 4))
        self._to_quat(rot.T)
        return rot

    def __call__(self, y: np.ndarray) -> SourcePose:
        buf = self._y
        self._y_head[...] = y
        pva = buf.take(self._pva)
        return SourcePose(pva[0], self._rotations(buf, self._axes), pva[1], pva[2],
                          np.greater(self._y_contacts, 0.5), -1, None, True)

    def tick(self, y_tick: np.ndarray, velocities) -> SourcePose:
        """The pose from the tick columns of a pose vector (:func:`lmm.nn.pose_vector_tick_columns`, in
        that order), its velocities from ``velocities()`` (the vector's velocity columns,
        :func:`lmm.nn.pose_vector_velocity_columns`) when first read: the values :meth:`__call__` gives
        for the whole vector."""
        buf = self._t
        self._t_head[...] = y_tick
        positions = buf.take(self._t_pos)
        rot = self._rotations(buf, self._t_axes)
        vel0, ang0 = self._t_root_slices
        root = (buf[vel0].tolist(), buf[ang0].tolist())
        later = _LaterVelocities(velocities, root, self.n_bones)
        return SourcePose(positions, rot, later.velocities, later.angular_velocities,
                          np.greater(self._t_contacts, 0.5), -1, root, True)


class _LaterVelocities:
    """A decoded pose's velocities and angular velocities (J, 3) each, float64, made on first read of
    either from the velocity columns ``velocities()`` gives and bone 0's (``root``, float lists)."""
    __slots__ = ("_fn", "_root", "_n", "_both")

    def __init__(self, velocities, root, n_bones: int):
        self._fn, self._root, self._n, self._both = velocities, root, n_bones, None

    def _make(self):
        if self._both is None:
            both = np.empty((2, self._n, 3))
            both[0, 0], both[1, 0] = self._root
            both[:, 1:] = np.asarray(self._fn()).reshape(2, self._n - 1, 3)
            self._both = both
        return self._both

    def velocities(self) -> np.ndarray:
        return self._make()[0]

    def angular_velocities(self) -> np.ndarray:
        return self._make()[1]


def decode_source_pose(y: np.ndarray, n_bones: int, slices: dict | None = None) -> SourcePose:
    """A decompressor output vector as a :class:`SourcePose` (float64; bone 0 carries root velocities);
    a controller keeps a :class:`PoseDecoder` instead of building one per pose."""
    return PoseDecoder(n_bones)(y)
