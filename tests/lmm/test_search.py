"""Search: the accelerated index returns exactly the brute-force answer (best frame, cost, ordered top-K
and per-channel costs), on synthetic data, on the default database and on 10,000 queries from runs."""
import copy

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from lmm.data.inputs import builtin, builtin_names
from lmm.mm import MotionMatchingController
from lmm.search import SearchIndex, brute_force_search, candidate_mask
from lmm.tuning import Tuning


def same(a, b) -> bool:
    return (a.best_frame == b.best_frame and a.best_cost == b.best_cost and np.array_equal(a.frames, b.frames)
            and np.array_equal(a.costs, b.costs) and np.array_equal(a.bias, b.bias)
            and np.array_equal(a.channel_costs, b.channel_costs))


def test_semantics_on_a_tiny_database():
    X = np.zeros((40, 2), np.float32)
    X[:, 0] = np.arange(40)          # frame i sits at x = i
    mask = candidate_mask(40, [0, 20], [20, 40], exclude_end=3)
    assert not mask[17:20].any() and not mask[37:].any() and mask[:17].all()
    q = np.array([10.2, 0.0], np.float32)
    # no playing frame: the nearest frame wins
    r = brute_force_search(X, q, mask, current=-1, top_k=3)
    assert list(r.frames) == [10, 11, 9]
    # playing frame 10: frames within the window are out, the playing one competes without bias
    r = brute_force_search(X, q, mask, current=10, transition_cost=0.5, exclude_window=2, top_k=3)
    assert list(r.frames) == [10, 13, 7] and r.bias[0] == 0 and r.bias[1] == np.float32(0.5)
    assert r.costs[1] == pytest.approx((13 - 10.2) ** 2 + 0.5, rel=1e-6)
    # a big transition cost keeps the playing frame even when it is far
    r = brute_force_search(X, np.array([30.0, 0], np.float32), mask, current=10, transition_cost=1000.0)
    assert r.best_frame == 10
    # a playing frame in the excluded end of its range cannot continue
    r = brute_force_search(X, np.array([18.0, 0], np.float32), mask, current=18, exclude_window=0)
    assert r.best_frame == 16
    # per-channel breakdown sums to the feature cost
    r = brute_force_search(X, q, mask, top_k=4, slices=[slice(0, 1), slice(1, 2)])
    assert np.allclose(r.channel_costs.sum(1), r.costs)


def test_ties_keep_playing_then_lowest_frame():
    X = np.zeros((200, 3), np.float32)
    mask = np.ones(200, bool)
    q = np.zeros(3, np.float32)
    for search in (lambda **k: brute_force_search(X, q, mask, **k), lambda **k: SearchIndex(X).search(q, mask, **k)):
        r = search(current=100, exclude_window=5, top_k=4)
        assert list(r.frames) == [100, 0, 1, 2]


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(5, 700), st.integers(1, 9), st.integers(-1, 699),
       st.integers(0, 30), st.integers(1, 12), st.floats(0, 3), st.booleans())
def test_accelerated_equals_brute_force_on_random_data(seed, n, d, current, window, k, tc, clustered):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, d)).astype(np.float32)
    if clustered:  # duplicates and ties
        X = np.round(np.cumsum(X, axis=0) * 0.1, 1).astype(np.float32)
    current = current if current < n else -1
    mask = rng.random(n) > 0.2
    q = (X[rng.integers(n)] + rng.normal(size=d) * 0.3).astype(np.float32)
    # hints may lie outside the frames (a controller's candidates advanced past the end): only speed depends on them
    hint = rng.integers(-3 * n, 3 * n, size=rng.integers(0, 12))
    index = SearchIndex(X)
    args = dict(current=current, transition_cost=tc, exclude_window=window, top_k=k)
    ref = brute_force_search(X, q, mask, **args)
    assert same(index.search(q, mask, **args), ref)
    assert same(index.search(q, mask, hint=hint, **args), ref)


def test_database_queries_and_weight_changes(db, features):
    feats = copy.copy(features)
    mask = candidate_mask(db.n_frames, db.range_starts, db.range_stops, 20)
    rng = np.random.default_rng(1)
    index = SearchIndex(feats.normalized)
    for weights in (None, [0.0, 0.75, 1.0, 3.0, 1.0, 0.2, 1.5]):
        if weights is not None:
            assert feats.set_weights(weights)
            assert index.update(feats.normalized) and not index.update(feats.normalized)
        X = feats.normalized
        for _ in range(150):
            f = int(rng.integers(db.n_frames))
            q = X[int(rng.integers(db.n_frames))].copy()
            q[15:] = X[f, 15:] + rng.normal(size=12).astype(np.float32) * 0.5  # another trajectory
            args = dict(current=f, transition_cost=float(rng.choice([0.0, 0.3])), exclude_window=20, top_k=8,
                        slices=feats.slices)
            assert same(index.search(q, mask, **args), brute_force_search(X, q, mask, **args))


def collect_run_queries(db, features, n_queries):
    """(query, frame, hint) at every search of runs of every built-in scenario, searching every tick."""
    scenarios = builtin_names((1,))
    seconds = n_queries / 60.0 / len(scenarios) + 0.5
    out = []
    for name in scenarios:
        tuning = Tuning()
        tuning.search_interval_s = 0.0
        c = MotionMatchingController(db, features, tuning)
        c.search_log = []
        log = builtin(name, seconds)
        for i in range(int(seconds * 60)):
            c.step(log.at(i / 60), 1 / 60)
        out += [(q, f, h, c) for q, f, h in c.search_log]
    return out[:n_queries]


@pytest.mark.slow
def test_ten_thousand_run_queries_are_exact(db, features):
    queries = collect_run_queries(db, features, 10_000)
    assert len(queries) == 10_000
    c = queries[0][3]
    mask = c.candidate_mask()
    X = c.features.normalized
    index = SearchIndex(X)
    args = dict(transition_cost=0.0, exclude_window=20, top_k=8, slices=features.slices)
    mismatches = 0
    for q, frame, hint, _ in queries:
        ref = brute_force_search(X, q, mask, current=frame, **args)
        res = index.search(q, mask, current=frame, hint=hint, **args)
        mismatches += not same(res, ref)
    assert mismatches == 0
    # its speed is a benchmark, not a test: `lmm-studio bench` (search.speedup) and bench/search_tail.py


def test_the_index_reads_the_features_padded_buffer_without_a_copy(db, features):
    """Features keep their normalised rows in a buffer padded with copies of the last row, which the
    index's blocks read in place (51 MB less on the 0.5 M-frame set); any other array is padded by a
    copy, with the same answers."""
    feats = copy.copy(features)
    feats.set_weights([1.0, 0.5, 1.0, 2.0, 1.0, 0.7, 1.5])        # a rescale: a new padded buffer
    X = feats.normalized
    assert len(X) == db.n_frames and X.base is not None and len(X.base) % feats.ROW_MULTIPLE == 0
    assert (X.base[len(X):] == X[-1]).all()
    index = SearchIndex(X)
    assert np.shares_memory(index.rows, X) and index.nbytes() < X.nbytes / 2
    copied = SearchIndex(X.copy())                                 # no padded buffer behind it
    assert not np.shares_memory(copied.rows, X)
    assert np.array_equal(copied.rows, index.rows)
    rng = np.random.default_rng(5)
    mask = np.ones(db.n_frames, bool)
    for _ in range(20):
        q = X[rng.integers(len(X))] + rng.normal(size=X.shape[1]).astype(np.float32) * 0.2
        assert same(index.search(q, mask, top_k=4), copied.search(q, mask, top_k=4))
