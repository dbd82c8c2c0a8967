"""Motion metrics from snapshots: foot skating, trajectory error, transitions, timings."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from lmm.metrics import MotionMetrics, format_metrics


def _snap(t, toes, contacts, root=(0, 0, 0), sim=(0, 0, 0), transitioned=False, searched=False, search_us=None):
    gp = np.zeros((23, 3), np.float32)
    gp[0] = root
    gp[5], gp[9] = toes
    timings = {"total": 100.0}
    if search_us is not None:
        timings["search"] = search_us
    return SimpleNamespace(time_s=t, pose=SimpleNamespace(global_positions=gp, global_rotations=np.ones((23, 4))),
                           foot_contacts=np.array(contacts), simulation_position=np.array(sim, float),
                           transitioned=transitioned, searched=searched, forced_search=False, timings_us=timings)


def test_skating_counts_only_feet_in_contact(db):
    m = MotionMetrics(db)
    dt = 0.1
    for i in range(11):
        # left toe slides 1 cm per tick (10 cm/s) in contact; right moves fast in the air
        m.update(_snap(i * dt, [(0.01 * i, 0, 0), (0, 0, 1.0 * i)], [True, False], root=(0.1, 0, 0),
                       transitioned=(i == 3), searched=(i % 2 == 0), search_us=50.0))
    r = m.result()
    assert r["foot_skating_cm_s"] == pytest.approx(10.0)
    assert r["foot_skating_left_cm_s"] == pytest.approx(10.0) and math.isnan(r["foot_skating_right_cm_s"])
    assert r["trajectory_error_mean_m"] == pytest.approx(0.1) and r["trajectory_error_max_m"] == pytest.approx(0.1)
    assert r["transitions"] == 1 and r["transitions_per_s"] == pytest.approx(1.0)
    assert r["searches"] == 6 and r["search_us_median"] == 50.0 and r["step_us_median"] == 100.0
    assert r["non_finite_ticks"] == 0 and "foot_skating_cm_s" in format_metrics(r)


def test_vertical_motion_is_not_skating(db):
    m = MotionMetrics(db)
    for i in range(5):
        m.update(_snap(i / 60, [(0, 0.01 * i, 0), (0, 0, 0)], [True, True]))
    assert m.result()["foot_skating_cm_s"] == pytest.approx(0.0)


def test_one_skating_rule_for_streams_and_arrays(db):
    """lmm-studio run streams ticks through MotionMetrics, eval hands FootSkating whole arrays: same number."""
    from lmm.metrics import FootSkating

    rng = np.random.default_rng(3)
    n, dt = 50, 1 / 60
    toes = np.cumsum(rng.normal(0, 0.01, (n, 2, 3)), axis=0)
    contacts = rng.random((n, 2)) < 0.6
    m = MotionMetrics(db)
    for i in range(n):
        m.update(_snap(i * dt, toes[i], contacts[i]))
    arrays = FootSkating()
    arrays.add(toes[:-1], toes[1:], contacts[1:], dt)   # (the snapshots hold float32 poses: rel 1e-6)
    assert arrays.mean_cm_s() == pytest.approx(m.result()["foot_skating_cm_s"], rel=1e-6)
    assert arrays.per_foot_cm_s() == pytest.approx([m.result()["foot_skating_left_cm_s"],
                                                    m.result()["foot_skating_right_cm_s"]], rel=1e-6)
    assert arrays.max == pytest.approx(m.result()["foot_skating_max_cm_s"], rel=1e-6)
    # the rule counts contact only: a raised toe that slides while marked in contact still skates
    high = FootSkating()
    high.add(np.array([[0, 1.0, 0], [0, 1.0, 0]]), np.array([[0.01, 1.0, 0], [0, 1.0, 0]]), [True, False], 0.1)
    assert high.mean_cm_s() == pytest.approx(10.0) and np.isnan(FootSkating().mean_cm_s())
