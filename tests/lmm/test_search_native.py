"""The compiled search filter (lmm/native/search.c through :mod:`lmm.search_native`): the runtime search
through it gives the brute force's answer bit for bit (frames, totals, biases, per-channel costs) on the
default data with tag biases, exclusion windows and playing frames, on a controller's own run-time queries and
on databases of any length (ties everywhere: test_search_tags);
without a compiler, one note and the numpy search, with the same answers; ``LMM_STUDIO_NATIVE=0`` turns it
off without a note."""
import numpy as np
import pytest

from lmm import search_native
from lmm.search import SearchIndex, biased_search, brute_force_search, candidate_mask


@pytest.fixture
def fresh_native():
    """The loader's state forgotten before and after (the next search builds or loads anew)."""
    search_native.reset()
    yield
    search_native.reset()


def _same(a, b) -> bool:
    both_nan = a.continuing_cost != a.continuing_cost and b.continuing_cost != b.continuing_cost
    return (np.array_equal(a.frames, b.frames) and np.array_equal(a.costs, b.costs)
            and np.array_equal(a.bias, b.bias) and np.array_equal(a.channel_costs, b.channel_costs)
            and (a.continuing_cost == b.continuing_cost or both_nan))


def _compiled_index(X):
    index = SearchIndex(X)
    if search_native.library() is None:
        pytest.skip(f"no compiled search here: {search_native.note()}")
    return index


def _runtime_queries(db, features, index, n, seed):
    """``n`` runtime-like group searches (tag groups with positive and negative biases, a playing frame and
    its window, top 1 with near frames or a ranked top K) with the brute force's answer to each."""
    rng = np.random.default_rng(seed)
    X = features.normalized
    mask = candidate_mask(db.n_frames, db.range_starts, db.range_stops, 10)
    tags = db.frame_tags
    groups_by_kind = [
        [(0.0, mask)],
        [(0.0, mask & (tags[:, 0] == 0)), (0.5, mask & (tags[:, 0] != 0))],
        [(-0.3, mask & (tags[:, 0] != 0)), (0.0, mask & (tags[:, 0] == 0) & (np.arange(db.n_frames) % 3 > 0))],
    ]
    for i in range(n):
        groups = groups_by_kind[i % 3]
        current = -1 if i % 5 == 0 else int(rng.integers(db.n_frames))
        near = X[min(max(current, 0) + int(rng.integers(0, 30)), db.n_frames - 1)]
        q = (near + rng.normal(0, [0.02, 0.2, 1.0][i % 3], X.shape[1])).astype(np.float32)
        k = 1 if i % 2 else int(rng.integers(2, 9))
        args = dict(current=current, transition_cost=float(rng.choice([0.0, 0.02, 0.5])),
                    exclude_window=int(rng.integers(0, 40)), top_k=k, slices=features.slices)
        fast = index.group_search(q, groups, near=8 if k == 1 else 0, **args)
        brute = biased_search(lambda **kw: brute_force_search(X, q, **kw), groups[0][1], None,
                              group_masks=groups, **args)
        yield i, fast, brute


def test_the_compiled_search_equals_the_brute_force_on_the_default_data(db, features, fresh_native):
    index = _compiled_index(features.normalized)
    for i, fast, brute in _runtime_queries(db, features, index, 300, 0):
        assert _same(fast, brute), i
    assert index._native, "the compiled filter ran"


def test_the_compiled_search_equals_the_brute_force_on_run_time_queries(db, features, fresh_native):
    """The queries, playing frames, hints and tag groups a motion matching controller searches with over 20 s
    of random input (the compiled path on), each searched again as the controller searches it at a tick."""
    from lmm.data.inputs import builtin
    from lmm.mm import MotionMatchingController

    index = _compiled_index(features.normalized)
    c = MotionMatchingController(db, features)
    c.search_log = []
    log, dt = builtin("random:1", 20.0), 1.0 / 60.0
    for i in range(1200):
        c.step(log.at(i * dt), dt)
    assert c.index._native, "the controller's search ran compiled"
    groups, X = c.tag_groups(), features.normalized
    args = dict(c.search_args(1), top_k=1)
    assert len(c.search_log) > 100
    for query, frame, hint in c.search_log:
        args["current"] = frame
        fast = index.group_search(query, groups, hint=hint, near=int(c.tuning.top_k), **args)
        brute = biased_search(lambda **kw: brute_force_search(X, query, **kw), groups[0][1], None,
                              group_masks=groups, **args)
        assert _same(fast, brute), frame


@pytest.mark.parametrize("n", [1, 33, 255, 257, 2049])
def test_databases_of_any_length_search_exactly(n, fresh_native):
    """Top blocks of 8 large blocks: a database that does not fill its last top block (or its first) leaves
    empty boxes there, which no search visits; every length still gives the brute force's answer."""
    rng = np.random.default_rng(n)
    X = np.cumsum(rng.normal(0, 0.1, (n, 5)), axis=0).astype(np.float32)   # smooth, like motion features
    index = _compiled_index(X)
    mask = np.ones(n, bool)
    for i in range(30):
        q = X[int(rng.integers(n))] + rng.normal(0, 0.3, 5).astype(np.float32)
        args = dict(current=int(rng.integers(-1, n)), transition_cost=0.1, exclude_window=3, top_k=1 + i % 4)
        fast = index.group_search(q, [(0.0, mask)], **args)
        assert _same(fast, brute_force_search(X, q, mask, **args)), i
    assert index._native


def test_top_boxes_hold_their_frames(features):
    """Each top box (and each large box grouped under it) holds every feature row of its frames."""
    index = SearchIndex(features.normalized)
    t_lo, t_hi, g_lo, g_hi = search_native.top_boxes(index, search_native.TOP_BLOCK)
    frames = search_native.TOP_BLOCK * index.large_block
    X = features.normalized
    for top in (0, 1, t_lo.shape[1] - 1):
        rows = X[top * frames:(top + 1) * frames]
        assert (t_lo[:, top] <= rows.min(axis=0)).all() and (t_hi[:, top] >= rows.max(axis=0)).all()
        for j in range(search_native.TOP_BLOCK):
            part = rows[j * index.large_block:(j + 1) * index.large_block]
            if len(part):
                assert (g_lo[top, :, j] <= part.min(axis=0)).all() and (g_hi[top, :, j] >= part.max(axis=0)).all()
            else:   # past the last frame: an empty box
                assert (g_lo[top, :, j] == np.inf).all() and (g_hi[top, :, j] == -np.inf).all()


def test_without_a_compiler_one_note_and_the_same_answers(db, features, fresh_native, monkeypatch, tmp_path, capfd):
    X = features.normalized
    compiled = [(f, b) for _, f, b in _runtime_queries(db, features, _compiled_index(X), 40, 3)]
    search_native.reset()
    monkeypatch.setenv("LMM_STUDIO_CACHE", str(tmp_path))            # no library built there
    for cc, why in (("lmm-no-such-compiler", "no C compiler"), ("false", "failed")):
        search_native.reset()
        monkeypatch.setenv("CC", cc)
        capfd.readouterr()
        for index in (SearchIndex(X), SearchIndex(X)):   # two indexes, one note
            fallback = [f for _, f, _ in _runtime_queries(db, features, index, 40, 3)]
            assert index._native is False
        err = capfd.readouterr().err
        assert err.count("note: compiled search unavailable") == 1 and why in err, err
        assert why in search_native.note()
        for (fast, brute), slow in zip(compiled, fallback):
            assert _same(slow, brute) and _same(fast, slow)
    assert not list(tmp_path.glob("native/*.so"))


def test_the_switch_turns_the_compiled_search_off_without_a_note(features, fresh_native, monkeypatch, capfd):
    monkeypatch.setenv(search_native.ENV_SWITCH, "0")
    index = SearchIndex(features.normalized)
    index.group_search(features.normalized[5], [(0.0, np.ones(len(features.normalized), bool))])
    assert index._native is False and search_native.note() == ""
    assert "note:" not in capfd.readouterr().err


def test_a_top_k_beyond_the_filter_runs_numpy(db, features, fresh_native):
    """The C filter ranks at most ``MAX_K`` frames; a larger top K is the numpy index's, exactly."""
    X = features.normalized
    index = _compiled_index(X)
    mask = candidate_mask(db.n_frames, db.range_starts, db.range_stops, 10)
    args = dict(current=100, transition_cost=0.02, exclude_window=20, top_k=search_native.MAX_K + 6)
    q = X[400] + np.float32(0.1)
    fast = index.group_search(q, [(0.0, mask)], **args)
    assert _same(fast, brute_force_search(X, q, mask, **args)) and fast.frames.size == args["top_k"]


def test_nearest_frames_is_the_brute_force_nearest_frame(features, fresh_native):
    """The projector training's targets (:meth:`SearchIndex.nearest_frames`): each query's nearest frame over
    every frame and its cost, as the brute force finds them (its costs and its first least frame)."""
    X = features.normalized
    index = _compiled_index(X)
    rng = np.random.default_rng(5)
    Q = (X[rng.integers(0, len(X), 300)] + rng.normal(0, 0.5, (300, X.shape[1]))).astype(np.float32)
    Q[:3] = X[[0, len(X) // 2, len(X) - 1]]          # on a frame: cost 0 (or a tie with an identical frame)
    frames, costs = index.nearest_frames(Q)
    for q, f, c in zip(Q, frames, costs):
        d = X - q
        all_costs = np.einsum("ij,ij->i", d, d)
        assert c == all_costs[f] and f == int(all_costs.argmin()), (f, int(all_costs.argmin()))


def test_nearest_frames_without_the_compiled_filter_is_none(features, fresh_native, monkeypatch):
    monkeypatch.setenv(search_native.ENV_SWITCH, "0")
    assert SearchIndex(features.normalized).nearest_frames(features.normalized[:4]) is None


def test_the_tick_filter_returns_ascending_frames_and_the_playing_frame_after_them(db, features, fresh_native):
    """``GroupFilter.tick``: the frames that may be in the answer, ascending in ``out[:n]``, and the playing
    frame at ``out[n]`` when it competes (the caller costs them with one gather); the brute force's answer is
    among them or is the playing frame."""
    X = features.normalized
    index = _compiled_index(X)
    mask = candidate_mask(db.n_frames, db.range_starts, db.range_stops, 10)
    frame_bias, _, small_min, large_min, *_ = index._groups([(0.0, mask)])
    native = search_native.group_filter(index)
    native._args.exact = 0           # numpy ranks: the frames and their rows come back
    rng = np.random.default_rng(11)
    playing = np.flatnonzero(mask)[rng.integers(0, mask.sum(), 40)]
    for current in playing:
        q = (X[current + 3] + rng.normal(0, 0.3, X.shape[1])).astype(np.float32)
        n = native.tick(q, frame_bias, small_min, large_min, np.float32(0.02), 0.0, int(current), 0.0, 1)
        assert n >= 0
        out = native.out[:n + 1].copy()
        assert np.all(np.diff(out[:n]) > 0) and out[n] == current and native.res[0] == 0.0
        assert np.array_equal(native.diff[:n + 1], X[out] - q)
        brute = brute_force_search(X, q, mask, current=int(current), transition_cost=0.02, exclude_window=0, top_k=1)
        assert brute.best_frame in set(out.tolist())


def test_the_filter_ranks_a_top_1_search_with_numpys_own_costs(db, features, fresh_native, monkeypatch):
    """The source's cost sum is numpy's row reduction bit for bit here, so a top-1 search is ranked in C (its
    answer the brute force's); with a numpy that sums otherwise (einsum replaced by a pairwise sum, which
    rounds differently) the check says so and numpy costs and ranks the frames, exactly as well."""
    X = features.normalized
    index = _compiled_index(X)
    native = search_native.group_filter(index)
    assert native.exact and search_native.sums_as_numpy(search_native.library(), X)
    ranked = []
    tick = search_native.GroupFilter.tick
    monkeypatch.setattr(search_native.GroupFilter, "tick",
                        lambda self, *a: (tick(self, *a), ranked.append(self.res[0]))[0])
    for i, fast, brute in _runtime_queries(db, features, index, 200, 6):
        assert _same(fast, brute), i
    assert sum(ranked) > 80, "most top-1 searches (half of them) ranked by the filter"

    einsum = np.einsum

    def other_order(spec, a, b, **kw):         # numpy summing in another order (pairwise over halves)
        if spec != "ij,ij->i" or a.shape[1] < 2:
            return einsum(spec, a, b, **kw)
        h = a.shape[1] // 2
        return einsum(spec, a[:, :h], b[:, :h]) + einsum(spec, a[:, h:], b[:, h:])

    monkeypatch.setattr(np, "einsum", other_order)
    assert not search_native.sums_as_numpy(search_native.library(), X)
    other = SearchIndex(X)
    ranked.clear()
    for i, fast, brute in _runtime_queries(db, features, other, 60, 7):
        assert _same(fast, brute), i        # the brute force sums the other way as well
    assert other._native and not other._native.exact and not any(ranked)


@pytest.mark.parametrize("tied", [6000, 300])
def test_more_tied_frames_than_the_filter_holds_fall_back_to_numpy(tied, fresh_native, monkeypatch):
    """Thousands of identical frames all tie with the answer: the filter gives up (more than it may return)
    and the numpy index answers, the brute force's answer exactly. A few hundred: more than the filter's
    rows-minus-query buffer holds (``DIFF_ROWS``), so they are gathered, exactly as well."""
    rng = np.random.default_rng(2)
    X = np.concatenate([np.zeros((tied, 4), np.float32), rng.normal(3, 1, (500, 4)).astype(np.float32)])
    index = _compiled_index(X)
    calls = []
    group_search = SearchIndex._group_search
    monkeypatch.setattr(SearchIndex, "_group_search", lambda self, *a: calls.append(1) or group_search(self, *a))
    mask = np.ones(len(X), bool)
    q = np.full(4, 0.01, np.float32)
    for current in (-1, tied + 100):
        args = dict(current=current, transition_cost=0.1, exclude_window=5, top_k=3)
        fast = index.group_search(q, [(0.0, mask)], **args)
        assert _same(fast, brute_force_search(X, q, mask, **args))
    assert tied > search_native.DIFF_ROWS            # both gathered: more rows than the buffer holds
    assert index._native and len(calls) == (2 if tied > 4096 else 0)


def test_top_1_ranking_of_a_few_frames_is_the_full_rankings(fresh_native):
    """``rank_top1`` (the compiled filter's few frames, keys as float32 scalars) gives ``rank_groups``'
    top 1, and ``rank``'s with one group of bias 0, or None where the least key ties (another frame, or the
    playing frame's total) and the full ranking must decide: random small cases with many exact ties."""
    from lmm.search_ranking import rank, rank_groups, rank_top1

    rng = np.random.default_rng(4)
    decided = undecided = 0
    for case in range(3000):
        n_frames = 40
        n = int(rng.integers(0, 7))
        frames = np.sort(rng.choice(n_frames, n, replace=False)).astype(np.int64)
        # costs on a coarse grid: equal costs and equal keys are common
        costs = (rng.integers(0, 6, n) * np.float32(0.25) + np.float32(1e-3) * rng.integers(0, 2, n)).astype(np.float32)
        one_group = case % 2 == 0
        b32 = [np.float32(0.0)] if one_group else [np.float32(0.0), np.float32(rng.choice([0.25, -0.25, 0.5]))]
        frame_group = rng.integers(0, len(b32), n_frames).astype(np.int64)
        frame_bias = np.array([b32[g] for g in frame_group], dtype=np.float32)
        tc = np.float32(rng.choice([0.0, 0.25, 0.02]))
        current = int(rng.integers(-1, n_frames))
        in_group = current >= 0 and current not in frames.tolist() and bool(rng.integers(0, 4))
        cont = float(np.float32(rng.integers(0, 6) * 0.25)) if in_group else float("nan")
        got = rank_top1(frames, costs, frame_bias, frame_group, b32, current, cont, in_group, tc)
        keys = costs + tc
        keys += frame_bias[frames]
        if one_group:
            want = rank(frames, costs, current, cont, float(tc), 1)
        else:
            want = rank_groups(frames, costs, keys, frame_group, b32, current, cont, in_group, tc, 1)
        if got is None:
            undecided += 1
            continue
        decided += 1
        for a, b in zip(got, want):
            assert a.dtype == b.dtype and np.array_equal(a, b), (case, got, want)
    assert decided > 1000 and undecided > 100
