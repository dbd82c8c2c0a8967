"""lmm.quat_scalar gives bit for bit the results of lmm.quat on float64 (the recordings depend on it)."""
import numpy as np
import pytest

from lmm import quat
from lmm import quat_scalar as qs


def _quats(rng, n):
    q = rng.normal(size=(n, 4))
    q[: n // 8, 1:] *= 1e-9          # near identity (the small-angle branches)
    q[n // 8: n // 4, 0] *= -1.0     # negative w
    q[n // 4: n // 4 + 5] = (1.0, 0.0, 0.0, 0.0)
    return quat.normalize(q)


def _vecs(rng, n):
    v = rng.normal(size=(n, 3)) * rng.uniform(1e-3, 10.0, size=(n, 1))
    v[: n // 10] *= 1e-10
    v[n // 10: n // 10 + 3] = 0.0
    return v


def _same(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return a.shape == b.shape and np.array_equal(a, b) and np.array_equal(np.signbit(a), np.signbit(b))


@pytest.mark.parametrize("seed", [0, 1])
def test_bit_identical_to_lmm_quat(seed):
    rng = np.random.default_rng(seed)
    a, b, v = _quats(rng, 3000), _quats(rng, 3000), _vecs(rng, 3000)
    raw = rng.normal(size=(3000, 4)) * rng.uniform(0.1, 10.0, size=(3000, 1))
    expected = {
        "mul": quat.mul(a, b), "mul_inv": quat.mul_inv(a, b), "mul_vec": quat.mul_vec(a, v),
        "inv_mul_vec": quat.inv_mul_vec(a, v), "abs_": quat.abs_(a), "normalize": quat.normalize(raw),
        "log": quat.log(a), "exp": quat.exp(v), "to_scaled_angle_axis": quat.to_scaled_angle_axis(a),
        "from_scaled_angle_axis": quat.from_scaled_angle_axis(v),
        "norm": np.linalg.norm(v, axis=-1), "norm4": np.linalg.norm(raw, axis=-1),
    }
    args = {"mul": (a, b), "mul_inv": (a, b), "mul_vec": (a, v), "inv_mul_vec": (a, v), "abs_": (a,),
            "normalize": (raw,), "log": (a,), "exp": (v,), "to_scaled_angle_axis": (a,),
            "from_scaled_angle_axis": (v,), "norm": (v,), "norm4": (raw,)}
    for name, want in expected.items():
        fn = getattr(qs, "norm" if name == "norm4" else name)
        got = np.array([fn(*(tuple(x[i].tolist()) for x in args[name])) for i in range(len(a))])
        assert _same(got, want), name


def test_the_comparison_can_fail():
    """A different association (x*x + (y*y + z*z)) is caught: the check above is not vacuous."""
    rng = np.random.default_rng(5)
    v = _vecs(rng, 3000)
    other = np.sqrt(v[:, 0] ** 2 + (v[:, 1] ** 2 + v[:, 2] ** 2))
    assert not _same(other, np.linalg.norm(v, axis=-1))
