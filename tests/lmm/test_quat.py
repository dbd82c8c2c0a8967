"""lmm.quat against slow, independent per-element implementations built on 3x3 / 4x4 matrices."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lmm import quat

ORDERS = ["xyz", "xzy", "yxz", "yzx", "zxy", "zyx"]


def slow_axis_matrix(axis: str, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=float)
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=float)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=float)


def slow_euler_matrix(angles, order: str) -> np.ndarray:
    """R = R(order[0], a0) @ R(order[1], a1) @ R(order[2], a2), one element at a time."""
    m = np.eye(3)
    for axis, a in zip(order, angles):
        m = m @ slow_axis_matrix(axis, float(a))
    return m


def slow_quat_matrix(q) -> np.ndarray:
    """Rotation matrix of a unit quaternion via Rodrigues' formula on its axis/angle."""
    w, v = float(q[0]), np.asarray(q[1:], dtype=float)
    s = np.linalg.norm(v)
    if s < 1e-15:
        return np.eye(3)
    angle = 2.0 * math.atan2(s, w)
    k = v / s
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx


def random_quats(rng, n):
    return quat.normalize(rng.normal(size=(n, 4)))


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def test_to_matrix_matches_rodrigues(rng):
    q = random_quats(rng, 200)
    fast = quat.to_matrix(q)
    for i in range(len(q)):
        np.testing.assert_allclose(fast[i], slow_quat_matrix(q[i]), atol=1e-12)


@pytest.mark.parametrize("order", ORDERS)
def test_from_euler_matches_matrix_product(order, rng):
    angles = rng.uniform(-math.pi, math.pi, size=(300, 3))
    q = quat.from_euler(angles, order)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-12)
    for i in range(len(angles)):
        np.testing.assert_allclose(slow_quat_matrix(q[i]), slow_euler_matrix(angles[i], order), atol=1e-12)


@pytest.mark.parametrize("order", ORDERS)
def test_from_euler_broadcasts(order, rng):
    angles = rng.uniform(-3, 3, size=(5, 7, 3))
    q = quat.from_euler(angles, order)
    assert q.shape == (5, 7, 4)
    np.testing.assert_allclose(q[2, 3], quat.from_euler(angles[2, 3], order), atol=1e-15)


@pytest.mark.parametrize("order", ORDERS)
def test_to_euler_inverts_from_euler(order, rng):
    # inside the principal range the angles themselves come back
    n = 500
    angles = np.stack([rng.uniform(-math.pi, math.pi, n),
                       rng.uniform(-math.pi / 2 + 1e-3, math.pi / 2 - 1e-3, n),
                       rng.uniform(-math.pi, math.pi, n)], axis=-1)
    back = quat.to_euler(quat.from_euler(angles, order), order)
    np.testing.assert_allclose(back, angles, atol=1e-9)


@pytest.mark.parametrize("order", ORDERS)
def test_to_euler_of_any_rotation_gives_the_same_rotation(order, rng):
    q = random_quats(rng, 300)
    angles = quat.to_euler(q, order)
    assert np.all(np.abs(angles[:, 1]) <= math.pi / 2 + 1e-12)
    for i in range(len(q)):
        np.testing.assert_allclose(slow_euler_matrix(angles[i], order), slow_quat_matrix(q[i]), atol=1e-9)


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("middle", [math.pi / 2, -math.pi / 2, math.pi / 2 - 1e-7, -math.pi / 2 + 1e-9])
def test_to_euler_gimbal_lock(order, middle, rng):
    n = 50
    angles = np.stack([rng.uniform(-3, 3, n), np.full(n, middle), rng.uniform(-3, 3, n)], axis=-1)
    back = quat.to_euler(quat.from_euler(angles, order), order)
    assert np.all(np.isfinite(back))
    for i in range(n):
        np.testing.assert_allclose(slow_euler_matrix(back[i], order), slow_euler_matrix(angles[i], order),
                                   atol=1e-6)


def test_mul_and_mul_vec_match_matrices(rng):
    a, b = random_quats(rng, 100), random_quats(rng, 100)
    v = rng.normal(size=(100, 3))
    ab = quat.mul(a, b)
    rv = quat.mul_vec(a, v)
    for i in range(100):
        np.testing.assert_allclose(slow_quat_matrix(ab[i]), slow_quat_matrix(a[i]) @ slow_quat_matrix(b[i]),
                                   atol=1e-12)
        np.testing.assert_allclose(rv[i], slow_quat_matrix(a[i]) @ v[i], atol=1e-12)


def test_matrix_round_trip(rng):
    q = random_quats(rng, 500)
    back = quat.from_matrix(quat.to_matrix(q))
    np.testing.assert_allclose(back, quat.abs_(q), atol=1e-12)


# -- the scalar form of each operation against its bulk form: the same bits on float64 (the recordings
#    depend on it) -----------------------------------------------------------------------------------

def _edge_quats(rng, n):
    q = rng.normal(size=(n, 4))
    q[: n // 8, 1:] *= 1e-9          # near identity (the small-angle branches)
    q[n // 8: n // 4, 0] *= -1.0     # negative w
    q[n // 4: n // 4 + 5] = (1.0, 0.0, 0.0, 0.0)
    return quat.normalize(q)


def _edge_vecs(rng, n):
    v = rng.normal(size=(n, 3)) * rng.uniform(1e-3, 10.0, size=(n, 1))
    v[: n // 10] *= 1e-10
    v[n // 10: n // 10 + 3] = 0.0
    return v


def _same_bits(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return a.shape == b.shape and np.array_equal(a, b) and np.array_equal(np.signbit(a), np.signbit(b))


@pytest.mark.parametrize("seed", [0, 1])
def test_every_scalar_form_gives_the_bits_of_its_bulk_form(seed):
    rng = np.random.default_rng(seed)
    a, b, v, o = _edge_quats(rng, 3000), _edge_quats(rng, 3000), _edge_vecs(rng, 3000), _edge_vecs(rng, 3000)
    raw = rng.normal(size=(3000, 4)) * rng.uniform(0.1, 10.0, size=(3000, 1))
    pairs = {  # scalar name: (bulk result, arguments)
        "mul_scalar": (quat.mul(a, b), (a, b)), "inv_mul_scalar": (quat.inv_mul(a, b), (a, b)),
        "mul_inv_scalar": (quat.mul_inv(a, b), (a, b)), "conj_scalar": (quat.conj(a), (a,)),
        "mul_vec_scalar": (quat.mul_vec(a, v), (a, v)), "inv_mul_vec_scalar": (quat.inv_mul_vec(a, v), (a, v)),
        "abs_scalar": (quat.abs_(a), (a,)), "normalize_scalar": (quat.normalize(raw), (raw,)),
        "log_scalar": (quat.log(a), (a,)), "exp_scalar": (quat.exp(v), (v,)),
        "to_scaled_angle_axis_scalar": (quat.to_scaled_angle_axis(a), (a,)),
        "from_scaled_angle_axis_scalar": (quat.from_scaled_angle_axis(v), (v,)),
        "angle_axis_difference_scalar": (quat.angle_axis_difference(a, b), (a, b)),
        "norm_scalar": (np.linalg.norm(v, axis=-1), (v,)),
    }
    for name, (want, args) in pairs.items():
        fn = getattr(quat, name)
        got = np.array([fn(*(tuple(x[i].tolist()) for x in args)) for i in range(len(a))])
        assert _same_bits(got, want), name
    got = np.array([quat.norm_scalar(tuple(r)) for r in raw.tolist()])
    assert _same_bits(got, np.linalg.norm(raw, axis=-1)), "norm_scalar of 4-vectors"
    # with an origin: origin + v + w t + u x t, summed in that order (single-pose forward kinematics)
    got = np.array([quat.mul_vec_scalar(tuple(a[i].tolist()), tuple(v[i].tolist()), tuple(o[i].tolist()))
                    for i in range(len(a))])
    w, u = a[:, :1], a[:, 1:]
    t = 2.0 * np.cross(u, v)
    assert _same_bits(got, o + v + w * t + np.cross(u, t)), "mul_vec_scalar with an origin"


def test_from_axis_angle_scalar_is_the_bulk_form_to_rounding(rng):
    axis = quat.normalize(rng.normal(size=(500, 3)))
    angle = rng.uniform(-7.0, 7.0, size=500)
    got = np.array([quat.from_axis_angle_scalar(tuple(x), float(t)) for x, t in zip(axis.tolist(), angle)])
    np.testing.assert_allclose(got, quat.from_axis_angle(axis, angle), rtol=0, atol=1e-15)


def test_the_bit_comparison_can_fail():
    """A different association (x*x + (y*y + z*z)) is caught: the check above is not vacuous."""
    rng = np.random.default_rng(5)
    v = _edge_vecs(rng, 3000)
    other = np.sqrt(v[:, 0] ** 2 + (v[:, 1] ** 2 + v[:, 2] ** 2))
    assert not _same_bits(other, np.linalg.norm(v, axis=-1))


def test_the_per_pose_fast_forms_against_the_bulk_forms():
    """to_scaled_angle_axis_into gives to_scaled_angle_axis(abs_(q)) bit for bit; the unnormalised
    exponential is from_scaled_angle_axis to rounding (its length is 1 to a few units in the last place)."""
    rng = np.random.default_rng(9)
    q = _edge_quats(rng, 2000)
    out = np.empty((len(q), 3))
    quat.to_scaled_angle_axis_into(q, out)
    assert _same_bits(out, quat.to_scaled_angle_axis(quat.abs_(q)))
    v = _edge_vecs(rng, 2000)
    np.testing.assert_allclose(quat.from_scaled_angle_axis_unnormalized(v), quat.from_scaled_angle_axis(v),
                               rtol=0, atol=1e-15)


def test_the_per_pose_product_is_the_bulk_product_bit_for_bit():
    rng = np.random.default_rng(10)
    for n in (1, 23, 60):
        a, b = _edge_quats(rng, n), _edge_quats(rng, n)
        assert _same_bits(quat.mul_pose(a, b), quat.mul(a, b))
        assert _same_bits(quat.mul_pose(a, b.astype(np.float32)), quat.mul(a, b.astype(np.float32)))
