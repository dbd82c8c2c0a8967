"""Springs: exact solutions of critically damped springs (checked against fine numerical integration)."""
import numpy as np
import pytest

from lmm import quat
from lmm.springs import (damper_exact, decay_spring_damper_exact, decay_spring_damper_exact_quat,
                         halflife_to_damping, simple_spring_damper_exact, simple_spring_damper_exact_quat,
                         spring_character_update)


def test_halflife_to_damping_value():
    assert halflife_to_damping(0.27) == pytest.approx(4 * np.log(2) / (0.27 + 1e-5))


def test_damper_halves_distance_every_halflife():
    x = damper_exact(0.0, 10.0, halflife=0.2, dt=0.2)
    assert x == pytest.approx(5.0, rel=1e-3)


def _integrate(x, v, goal, halflife, t, n=20000):
    """Semi-implicit Euler with tiny steps: x'' = -d x' - (d/2)^2 (x - goal), critically damped."""
    d = halflife_to_damping(halflife)
    h = t / n
    for _ in range(n):
        a = -d * v - (d * d / 4.0) * (x - goal)
        v = v + h * a
        x = x + h * v
    return x, v


@pytest.mark.parametrize("halflife", [0.05, 0.27, 0.5])
def test_spring_matches_integration(halflife):
    x, v = simple_spring_damper_exact(1.0, -2.0, 0.3, halflife, 0.25)
    xi, vi = _integrate(1.0, -2.0, 0.3, halflife, 0.25)
    assert x == pytest.approx(xi, abs=2e-3) and v == pytest.approx(vi, abs=2e-2)


def test_decay_is_spring_to_zero_and_vectorised():
    x = np.array([[1.0, -2.0, 0.5], [0.0, 3.0, 1.0]])
    v = np.array([[0.5, 0.0, -1.0], [1.0, 1.0, 1.0]])
    a, b = decay_spring_damper_exact(x, v, 0.1, 1 / 60)
    c, d = simple_spring_damper_exact(x, v, np.zeros_like(x), 0.1, 1 / 60)
    assert np.allclose(a, c) and np.allclose(b, d)
    x_late, _ = decay_spring_damper_exact(x, v, 0.1, 5.0)
    assert np.abs(x_late).max() < 1e-10


def test_character_spring_converges_and_integrates_velocity():
    zero, goal = (0.0, 0.0, 0.0), (2.0, 0.0, -1.0)
    # many small steps equal one big step (exact solution)
    xs, vs, as_ = zero, zero, zero
    for _ in range(60):
        (xs, vs, as_), = spring_character_update(xs, vs, as_, goal, 0.27, (1 / 60,))
    (xb, vb, ab), = spring_character_update(zero, zero, zero, goal, 0.27, (1.0,))
    assert np.allclose(xs, xb, atol=1e-9) and np.allclose(vs, vb, atol=1e-9)
    # horizons in one call (trajectory prediction)
    xh = np.array([x for x, _, _ in spring_character_update(zero, zero, zero, goal, 0.27, (1 / 3, 2 / 3, 1.0))])
    assert xh.shape == (3, 3) and np.allclose(xh[-1], xb)
    (x10, v10, _), = spring_character_update(zero, zero, zero, goal, 0.27, (10.0,))
    assert np.allclose(v10, goal, atol=1e-6)


def test_zero_halflife_snaps_without_nan():
    (x, v, a), = spring_character_update((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 0.0,
                                         (1 / 60,))
    assert np.isfinite(x).all() and np.allclose(v, 1.0)


def test_quaternion_spring_reaches_goal_the_short_way():
    q = quat.from_axis_angle(np.array([0.0, 1.0, 0.0]), np.radians(170.0))
    goal = quat.from_axis_angle(np.array([0.0, 1.0, 0.0]), np.radians(-170.0))
    q1, w1 = simple_spring_damper_exact_quat(q, np.zeros(3), goal, 0.1, 1 / 60)
    # the short way from 170 to -170 degrees goes through 180 (positive rotation about +Y)
    assert w1[1] > 0
    q2, _ = simple_spring_damper_exact_quat(q, np.zeros(3), goal, 0.1, 3.0)
    assert abs(abs(np.dot(q2, goal)) - 1.0) < 1e-9
    qd, wd = decay_spring_damper_exact_quat(quat.normalize(np.array([0.9, 0.1, 0.3, 0.0])), np.zeros(3), 0.1, 3.0)
    assert abs(abs(qd[0]) - 1.0) < 1e-9


def test_decay_of_one_float_is_the_array_form_bit_for_bit():
    from lmm.springs import decay_spring_damper_scalar
    rng = np.random.default_rng(12)
    x, v = rng.normal(size=500), rng.normal(size=500) * 3
    for halflife, dt in ((0.1, 1 / 60), (0.0, 1 / 60), (0.35, 0.5)):
        want_x, want_v = decay_spring_damper_exact(x, v, halflife, dt)
        y = float(halflife_to_damping(halflife)) / 2.0
        e = float(np.exp(-y * dt))
        got = np.array([decay_spring_damper_scalar(a, b, y, e, dt) for a, b in zip(x.tolist(), v.tolist())])
        assert np.array_equal(got[:, 0], want_x) and np.array_equal(got[:, 1], want_v)


def test_one_rotation_spring_is_bit_identical_to_the_vectorised_form():
    """The plain-float path of simple_spring_damper_exact_quat (one rotation, scalar dt or a few horizons)
    against the numpy path it replaces, on the same arguments."""
    from lmm.springs import _spring_damper_exact_quat_arrays, simple_spring_damper_exact_quat

    rng = np.random.default_rng(7)
    for i in range(300):
        q = quat.normalize(rng.normal(size=4))
        goal = quat.normalize(rng.normal(size=4)) if i % 5 else q.copy()
        w = rng.normal(size=3) * (0.0 if i % 7 == 0 else 3.0)
        halflife = float(rng.uniform(0.0, 0.5))
        for dt in (1 / 60, float(rng.uniform(0, 2)), np.array([20, 40, 60]) / 60.0):
            got_q, got_w = simple_spring_damper_exact_quat(q, w, goal, halflife, dt)
            want_q, want_w = _spring_damper_exact_quat_arrays(q, w, goal, halflife, dt)
            assert got_q.shape == want_q.shape and np.array_equal(got_q, want_q)
            assert got_w.shape == want_w.shape and np.array_equal(got_w, want_w)
