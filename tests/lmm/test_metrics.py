"""Motion metrics from snapshots: foot skating, trajectory error, transitions, timings."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from lmm.metrics import MotionMetrics, format_metrics


def _snap(t, toes, contacts, root=(0, 0, 0), sim=(0, 0, 0), transitioned=False, searched=False, search_us=None,
          frame=-1):
    gp = np.zeros((23, 3), np.float32)
    gp[0] = root
    gp[5], gp[9] = toes
    timings = {"total": 100.0}
    if search_us is not None:
        timings["search"] = search_us
    return SimpleNamespace(time_s=t, pose=SimpleNamespace(global_positions=gp, global_rotations=np.ones((23, 4))),
                           foot_contacts=np.array(contacts), simulation_position=np.array(sim, float),
                           transitioned=transitioned, searched=searched, forced_search=False, timings_us=timings,
                           matched_frame=frame)


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


def test_ground_skating_counts_fast_steps_at_ground_level_only():
    from lmm.metrics import ground_skating

    dt = 1 / 60
    n = 61
    toes = np.zeros((n, 2, 3))
    # left: 1 s on the ground (y = 0.01), sliding 60 cm/s for the first half second, still for the second
    toes[:, 0, 0] = np.concatenate([np.arange(31) * 0.01, np.full(30, 0.30)])
    toes[:, 0, 1] = 0.01
    # right: fast (1.2 m/s) but 10 cm up: never ground level
    toes[:, 1, 1] = 0.10
    toes[:, 1, 2] = np.arange(n) * 0.02
    g = ground_skating(toes, 60.0, floor_m=0.0)   # taken over 1/30 s steps: 30 of them per toe
    assert g["ground_steps"] == 30 and g["skating_steps"] == 15 and g["fraction"] == pytest.approx(0.5)
    # with the floor from the clip itself (each toe's low percentile) the raised toe is at its own ground
    own = ground_skating(toes, 60.0)
    assert own["ground_steps"] == 60 and own["skating_steps"] == 45
    # the same motion at 30 fps gives the same counts: the figure does not depend on the frame rate
    assert ground_skating(toes[::2], 30.0, floor_m=0.0) == g
    assert math.isnan(ground_skating(toes[:, :, :] + [0, 1.0, 0], 60.0, floor_m=0.0)["fraction"])


def test_one_ground_skating_rule_for_streams_and_arrays(db):
    from lmm.metrics import ground_skating

    rng = np.random.default_rng(5)
    n, dt = 400, 1 / 60
    toes = np.cumsum(rng.normal(0, 0.006, (n, 2, 3)), axis=0)
    toes[..., 1] = np.abs(rng.normal(0.02, 0.02, (n, 2)))
    toes = toes.astype(np.float32).astype(np.float64)  # what the snapshots hold
    m = MotionMetrics(db)
    for i in range(n):
        m.update(_snap(i * dt, toes[i], [False, False]))
    r = m.result()
    g = ground_skating(toes, 1 / dt)
    assert (r["ground_skating_steps"], r["ground_skating_ground_steps"]) == (g["skating_steps"], g["ground_steps"])
    assert r["ground_skating_fraction"] == g["fraction"] and 0 < g["fraction"] < 1
    assert m.ground.heights.nbytes < 100_000  # bounded: histograms, not frames


def test_source_ground_skating_is_the_same_rule_per_range(db):
    from lmm.metrics import ground_skating, source_ground_skating

    src = source_ground_skating(db)
    toes = [db.bone("left_toe"), db.bone("right_toe")]
    fast = ground = 0
    for r, (a, b) in enumerate(zip(db.range_starts, db.range_stops)):
        if not db.range_mirrored[r]:
            g = ground_skating(db.global_transforms(slice(int(a), int(b)))[1][:, toes], db.fps)
            fast, ground = fast + g["skating_steps"], ground + g["ground_steps"]
    assert (src["skating_steps"], src["ground_steps"]) == (fast, ground) and ground > 0
    assert 0.0 <= src["fraction"] < 0.2  # mocap barely skates


def test_duration_stats_median_is_exact_then_within_a_bin():
    from lmm.metrics import DurationStats

    s = DurationStats()
    assert math.isnan(s.median()) and math.isnan(s.mean())
    for v in (5.0, 1.0, 3.0):
        s.add(v)
    assert s.median() == 3.0 and s.mean() == 3.0 and s.count == 3
    rng = np.random.default_rng(0)
    values = rng.lognormal(np.log(300.0), 0.8, size=50_000)     # microseconds, a long tail
    s = DurationStats()
    for v in values:
        s.add(v)
    assert s.count == values.size and s.mean() == pytest.approx(values.mean(), rel=1e-9)
    assert s.median() == pytest.approx(np.median(values), rel=0.01)
    assert s.quantile(0.95) == pytest.approx(np.quantile(values, 0.95), rel=0.01)
    s.add(0.0)
    s.add(1e30)                                                 # out of range: counted at the ends
    assert s.count == values.size + 2


def test_metrics_memory_does_not_grow_with_the_run(db):
    """A long run feeds millions of ticks: after warming up, 20,000 more keep the metrics' memory
    constant (the per-tick timing lists grew ~38 bytes per tick)."""
    import tracemalloc

    m = MotionMetrics(db)
    snaps = [_snap(i / 60, [(0.001 * i, 0, 0), (0, 0, 0.001 * i)], [True, i % 3 == 0], searched=(i % 2 == 0),
                   search_us=40.0 + i % 7) for i in range(64)]
    for i in range(5000):
        m.update(snaps[i % 64])
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    for i in range(20_000):
        m.update(snaps[i % 64])
    grown = tracemalloc.get_traced_memory()[0] - before
    tracemalloc.stop()
    assert grown < 20_000, grown          # bytes, for 20,000 ticks: < 1 byte per tick
    assert m.result()["ticks"] == 25_000


def test_tag_shares_count_the_playing_frames(db):
    """Per tag, the share of ticks whose playing frame's range has it, over the ticks that play a database
    frame (-1: none, e.g. the learned controller without its debug comparison)."""
    walk = int(np.flatnonzero(db.tag_mask("walk"))[0])
    other = int(np.flatnonzero(~db.tag_mask("walk"))[0])
    m = MotionMetrics(db)
    for i, frame in enumerate([walk, walk, -1, walk, other, db.n_frames]):
        m.update(_snap(i / 60, [(0, 0, 0), (0, 0, 0)], [True, True], frame=frame))
    r = m.result()
    assert set(k for k in r if k.startswith("tag_share_")) == {f"tag_share_{t}" for t in db.tag_names}
    assert r["tag_share_walk"] == pytest.approx(0.75)
    for k, t in enumerate(db.tag_names):   # the same count, from the frames' own tags
        expected = (3 * int(db.frame_tags[walk, k]) + int(db.frame_tags[other, k])) / 4
        assert r[f"tag_share_{t}"] == pytest.approx(expected), t
    none = MotionMetrics(db)
    none.update(_snap(0.0, [(0, 0, 0), (0, 0, 0)], [True, True]))
    assert all(math.isnan(none.result()[f"tag_share_{t}"]) for t in db.tag_names)
