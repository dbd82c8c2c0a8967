"""Tags in the search: a per-tag cost bias and the idle set (a tag filter while the stick is released)."""
from __future__ import annotations

import copy

import numpy as np
import pytest

from lmm.data.inputs import builtin
from lmm.mm import MotionMatchingController
from lmm.search import SearchIndex, biased_search, brute_force_search, candidate_mask
from lmm.tuning import Tuning, TuningError


@pytest.fixture
def mm(db, features):
    c = MotionMatchingController(db, features, Tuning())
    c.reset()
    return c


def _far_frame(db, frame):
    """A playing frame far from ``frame`` (so the exclusion window does not hide it)."""
    return (frame + db.n_frames // 2) % db.n_frames


def test_a_tag_bias_changes_the_chosen_frame(mm, db):
    idle = np.flatnonzero(db.tag_mask("idle") & mm.candidate_mask())   # not in the excluded end of a range
    f0 = int(idle[len(idle) // 2])
    query = mm.features.normalized[f0].copy()
    mm.frame = _far_frame(db, f0)
    assert mm.search(query).best_frame == f0          # its own features: cost 0
    mm.tuning.tag_bias["idle"] = 5.0
    res = mm.search(query)
    assert res.best_frame != f0 and "idle" not in db.tags_of(res.best_frame)
    mm.tuning.tag_bias["idle"] = 0.0
    mm.tuning.tag_bias["run"] = -5.0                  # a bonus: the best frame now runs
    res = mm.search(query)
    assert "run" in db.tags_of(res.best_frame) and res.best_cost < 0
    assert mm.search(query, accelerated=False).best_frame == res.best_frame


def test_the_idle_set_never_returns_a_frame_outside_it(mm, db):
    idle = db.tag_mask("idle")
    rng = np.random.default_rng(3)
    mm.stick_released_s = 10.0
    assert mm.idle_set_active()
    for bias in (0.0, 2.0):
        mm.tuning.tag_bias["walk"] = bias
        for _ in range(25):
            f = int(rng.integers(db.n_frames))
            query = mm.features.normalized[f] + rng.normal(0, 0.3, mm.features.normalized.shape[1]).astype(np.float32)
            mm.frame = int(rng.integers(db.n_frames))
            fast, slow = mm.search(query), mm.search(query, accelerated=False)
            assert idle[fast.frames].all() and idle[slow.frames].all()
            assert np.array_equal(fast.frames, slow.frames)
    assert mm.tag_error is None
    mm.stick_released_s = 0.0                          # stick pushed: every frame again
    assert not mm.idle_set_active()


def test_biased_search_matches_brute_force_with_the_bias_added(features, db):
    rng = np.random.default_rng(5)
    X = features.normalized
    frame_bias = (db.frame_tags.astype(np.float32) @ rng.uniform(-1, 1, len(db.tag_names)).astype(np.float32))
    mask = np.ones(db.n_frames, dtype=bool)
    for _ in range(5):
        q = X[int(rng.integers(db.n_frames))]
        res = biased_search(lambda **kw: brute_force_search(X, q, **kw), mask, frame_bias, top_k=4)
        total = ((X - q) ** 2).sum(axis=1) + frame_bias
        assert res.best_cost == pytest.approx(float(total.min()), abs=1e-3)


def _same(a, b):
    return (np.array_equal(a.frames, b.frames) and np.array_equal(a.costs, b.costs)
            and np.array_equal(a.bias, b.bias) and np.array_equal(a.channel_costs, b.channel_costs)
            and (a.continuing_cost == b.continuing_cost or (np.isnan(a.continuing_cost) and np.isnan(b.continuing_cost))))


def test_the_one_pass_group_search_equals_one_search_per_group(features, db):
    """Tag groups (biases of either sign, the idle set, one unbiased group), with and without a hint,
    the playing frame in or out of the candidates: frames, totals, biases and breakdown all identical to
    one accelerated search per group, and to the brute force."""
    rng = np.random.default_rng(11)
    X = features.normalized
    index = SearchIndex(X)
    base = candidate_mask(db.n_frames, db.range_starts, db.range_stops, 10)
    idle = base & db.tag_mask("idle")
    tags = db.frame_tags.astype(np.float32)
    setups = [(base, np.zeros(len(db.tag_names), np.float32)), (idle, np.zeros(len(db.tag_names), np.float32))]
    for _ in range(3):
        setups.append((base, rng.choice([-1.0, 0.0, 0.5, 1.0, 3.0], len(db.tag_names)).astype(np.float32)))
    tried = 0
    for mask, bias in setups:
        fb = tags @ bias
        groups = [(float(b), mask & (fb == b)) for b in np.unique(fb[mask])]
        for i in range(12):
            f = int(rng.integers(db.n_frames))
            q = X[f] + rng.normal(0, 0.2 * (i % 3), X.shape[1]).astype(np.float32)
            current = int(rng.integers(db.n_frames)) if i % 4 else f
            hint = None if i % 2 else rng.integers(0, db.n_frames, 6)
            args = dict(current=current, transition_cost=0.05 * (i % 3), exclude_window=20, top_k=1 + i % 8,
                        slices=features.slices)
            one = index.group_search(q, groups, hint=hint, **args)
            per = biased_search(lambda **kw: index.search(q, hint=hint, **kw), mask, None, group_masks=groups, **args)
            brute = biased_search(lambda **kw: brute_force_search(X, q, **kw), mask, None, group_masks=groups, **args)
            assert _same(one, per) and _same(one, brute), (bias, i)
            tried += 1
    assert tried == 60


def test_an_idle_set_that_matches_nothing_is_one_line_and_searches_everything(db, features):
    untagged = copy.copy(db)
    untagged.set_tags([()] * db.n_ranges)
    c = MotionMatchingController(untagged, features, Tuning())
    c.reset()
    c.stick_released_s = 10.0
    res = c.search(c.features.normalized[100])
    assert res.best_frame >= 0
    assert c.tag_error is not None and "'idle_set_enabled'" in c.tag_error and "\n" not in c.tag_error
    c.tuning.tag_bias["sprint"] = 1.0
    c.stick_released_s = 0.0
    c.search(c.features.normalized[100])
    assert "'tag_bias.sprint'" in c.tag_error


def test_tag_bias_values_are_validated():
    with pytest.raises(TuningError, match=r"'tag_bias.run'"):
        Tuning.from_dict({"tag_bias": {"run": 50.0}})
    t = Tuning.from_dict({"tag_bias": {"run": -1.0, "mine": 2.0}})
    t.reset_group("search")
    assert t.tag_bias["run"] == 0.0 and t.tag_bias["mine"] == 0.0


def test_after_the_stick_is_released_the_character_plays_an_idle_range(mm, db):
    log = builtin("stop-and-go", 8.0)   # runs 2.5 s, then stands 1.5 s
    dt = 1.0 / 60.0
    seen = []
    for i in range(int(4.0 / dt)):
        t = i * dt
        _, snap = mm.step(log(t), dt)
        if 2.5 + mm.tuning.idle_delay_s + 0.25 <= t < 4.0:
            seen.append("idle" in db.tags_of(snap.matched_frame))
    assert seen and all(seen)


def test_a_filter_that_matches_nothing_is_reported_in_the_snapshot():
    """The idle set on a database with no idle range: every frame is searched, and the snapshot says why
    in one line naming the tuning field (the studio's Search Candidates panel shows it)."""
    from lmm.controller import InputState
    from lmm.data.build import load_or_build
    from lmm.factory import make_controller
    from lmm.features import build_features
    import json, tempfile
    from pathlib import Path
    from lmm import DEFAULT_MANIFEST

    with tempfile.TemporaryDirectory() as d:
        m = Path(d) / "m.json"
        take = DEFAULT_MANIFEST.parent / "lafan1" / "obstacles3_subject4.bvh.gz"
        m.write_text(json.dumps({"name": "no-idle", "clips": [{"file": str(take), "ranges": [
            {"range": [2600, 2900], "tags": ["walk"]}]}]}))
        db, _ = load_or_build(m, cache_dir=Path(d) / "cache")
        ctrl = make_controller("mm", db, build_features(db))
        snap = None
        for _ in range(120):   # the stick stays released past idle_delay_s
            _, snap = ctrl.step(InputState(), 1.0 / 60.0)
        assert "tuning field 'idle_set_enabled'" in snap.search_note and "\n" not in snap.search_note
        _, snap = ctrl.step(InputState(left_y=1.0), 1.0 / 60.0)
        ctrl.tuning.idle_set_enabled = False
        _, snap = ctrl.step(InputState(), 1.0 / 60.0)
        _, snap = ctrl.step(InputState(), 1.0 / 60.0)
        assert snap.search_note == ""


def numpy_index(X):
    """A :class:`SearchIndex` that searches with numpy only (no compiled filter)."""
    index = SearchIndex(X)
    index._native = False
    return index


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("seed", range(4))
def test_the_one_pass_group_search_with_ties_everywhere(seed, compiled):
    """Integer features (many equal costs) and a bias so large that float32 totals of different costs round to
    the same value: the one-pass group search still ranks, cuts each group at K and merges exactly as one
    brute-force search per group does, the playing frame included, in or out of the candidates; with the
    compiled filter (lmm.search_native: it keeps every frame that may tie, numpy ranks them) and without."""
    rng = np.random.default_rng(seed)
    n = 700
    X = rng.integers(0, 3, size=(n, 3)).astype(np.float32)
    index = SearchIndex(X) if compiled else numpy_index(X)
    mask = candidate_mask(n, [0, 300], [300, n], 5)
    label = rng.integers(0, 3, n)
    # float32 steps are 2 at 2**24 and 4 at 2**25: totals a few apart round to one value, across groups too
    biases = [float(2 ** 24), float(2 ** 24 + 2), float(2 ** 24 - 2)] if seed % 2 else \
        [float(2 ** 25 + 4), float(2 ** 25), float(2 ** 25 - 4)]
    groups = [(b, mask & (label == g)) for g, b in enumerate(biases)]
    for i in range(40):
        q = rng.integers(0, 3, 3).astype(np.float32) + np.float32(0.5 * (i % 2))
        current = [-1, int(rng.integers(n)), 298][i % 3]
        # the ends reach into the padding; frames past them (-n .. 2n) are clipped
        hint = None if i % 4 == 1 else np.concatenate(([0, n - 1], rng.integers(-n, 2 * n, 6)))
        args = dict(current=current, transition_cost=[0.0, 0.3, 1.0][i // 3 % 3],
                    exclude_window=int(rng.integers(0, 4)), top_k=1 + i % 12)
        one = index.group_search(q, groups, hint=hint, **args)
        brute = biased_search(lambda **kw: brute_force_search(X, q, **kw), mask, None, group_masks=groups, **args)
        assert _same(one, brute), (seed, i)


def test_a_playing_frame_tied_with_a_better_candidate_by_rounding_keeps_its_group_order():
    """At bias 2**24 (float32 steps of 2) a candidate of cost 0.5 and the playing frame of cost 1 round to the
    same total. The playing frame's group ranks the candidate first (lower total) and cuts at K = 1 before the
    merge, whose tie rule (playing frame first) would otherwise pick the playing frame."""
    X = np.full((96, 2), 10.0, np.float32)
    X[10] = (0.5, 0.5)                      # cost 0.5
    X[50] = (1.0, 0.0)                      # the playing frame, cost 1
    mask = np.ones(96, bool)
    far = np.zeros(96, bool)
    far[80:] = True
    groups = [(float(2 ** 24), mask & ~far), (float(2 ** 24 + 64), far)]
    q = np.zeros(2, np.float32)
    args = dict(current=50, transition_cost=0.0, exclude_window=0, top_k=1)
    one = SearchIndex(X).group_search(q, groups, **args)
    brute = biased_search(lambda **kw: brute_force_search(X, q, **kw), mask, None, group_masks=groups, **args)
    assert list(brute.frames) == [10] and brute.costs[0] == np.float32(2 ** 24)
    assert _same(one, brute)


def test_a_top_1_group_search_that_no_block_survives_keeps_playing(features, db):
    """With a transition cost so large that the playing frame beats every other frame's bound, no block
    survives the cut: the top-1 search (the controller's tick search) keeps the playing frame, as the brute
    force does, and its near frames are the hint's seeds (the hinted frame and its neighbours), the only
    frames evaluated. (The numpy index's seeds: the compiled filter finds its own first bound.)"""
    X = features.normalized
    index = numpy_index(X)
    mask = candidate_mask(db.n_frames, db.range_starts, db.range_stops, 10)
    groups = [(0.0, mask & (db.frame_tags[:, 0] == 0)), (1.0, mask & (db.frame_tags[:, 0] != 0))]
    current = int(np.flatnonzero(mask)[len(np.flatnonzero(mask)) // 2])
    q = X[current].copy()
    args = dict(current=current, transition_cost=1e6, exclude_window=20, top_k=1, slices=features.slices)
    one = index.group_search(q, groups, hint=np.array([current + 100]), near=8, **args)
    brute = biased_search(lambda **kw: brute_force_search(X, q, **kw), mask, None, group_masks=groups, **args)
    assert _same(one, brute) and list(one.frames) == [current]
    assert sorted(one.near_frames.tolist()) == list(range(current + 98, current + 103))


def test_the_near_frames_of_a_top_1_search_make_the_next_hint(features, db):
    """``near``: up to that many candidate frames of least total among those evaluated (block frames and
    the hint's seeds), outside the playing frame's exclusion window and the answer's (the answer plays
    next, and its neighbours advance with it: they would make no seeds). Fed back as the next search's
    hint, as the controller does, they keep giving seeds: the search seldom falls back to its descent."""
    from lmm.search_ranking import least_frames

    keys = np.array([5.0, np.inf, 1.0, 3.0, np.inf, 2.0], np.float32)
    frames = np.arange(10, 16)
    assert sorted(least_frames(frames, keys, 3)) == [12, 13, 15]
    assert sorted(least_frames(frames, keys, 6)) == [10, 12, 13, 15]      # the infinite keys left out
    assert sorted(least_frames(frames, keys, 20)) == [10, 12, 13, 15]
    rng = np.random.default_rng(5)
    X = features.normalized
    index = numpy_index(X)      # the numpy index's seeds (the compiled filter needs no hint)
    mask = candidate_mask(db.n_frames, db.range_starts, db.range_stops, 10)
    groups = [(0.0, mask & (db.frame_tags[:, 0] == 0)), (1.0, mask & (db.frame_tags[:, 0] != 0))]
    window, hint, current, carried = 20, None, int(rng.integers(db.n_frames)), 0
    for i in range(40):
        q = X[min(current + 10, db.n_frames - 1)] + rng.normal(0, 0.05, X.shape[1]).astype(np.float32)
        args = dict(current=current, transition_cost=0.02, exclude_window=window, slices=features.slices)
        one = index.group_search(q, groups, top_k=1, near=8, hint=hint, **args)
        brute = biased_search(lambda **kw: brute_force_search(X, q, **kw), mask, None, group_masks=groups, top_k=1,
                              **args)
        assert _same(one, brute)
        near, best = one.near_frames, one.best_frame
        assert near.size <= 8 and mask[near].all() and np.all(np.abs(near - current) > window)
        if best != current:
            assert np.all(np.abs(near - best) > window)
        carried += near.size > 0
        # the controller: the answer plays on for 10 frames, the near frames advance with it
        current = best + 10 if best + 10 < db.n_frames and mask[best + 10] else int(rng.integers(db.n_frames))
        hint = near + 10 if near.size else None
    assert carried >= 36, carried


# -- excluded tags: a filter, where a bias is a cost ------------------------------------------------

def test_an_excluded_tag_is_never_returned_and_the_playing_frame_leaves_it(mm, db):
    """Every query looks for a run frame (its own features); with ``run`` excluded neither search returns a
    frame tagged run, and a playing frame in a run range no longer competes as the continuing pose."""
    run = db.tag_mask("run")
    frames = np.flatnonzero(run & mm.candidate_mask())
    rng = np.random.default_rng(5)
    picks = rng.choice(frames, 20, replace=False)
    assert all(mm.search(mm.features.normalized[f].copy()).best_frame == f
               for f in picks[:3] if (mm.__setattr__("frame", _far_frame(db, f)) or True))
    mm.tuning.tag_excluded["run"] = True
    for f in picks:
        query = mm.features.normalized[f].copy()
        mm.frame = int(f)                              # playing the very frame the query describes
        fast, slow = mm.search(query), mm.search(query, accelerated=False)
        assert not run[fast.frames].any() and np.array_equal(fast.frames, slow.frames)
        assert fast.best_frame != f
    assert mm.tag_error is None
    mm.tuning.tag_excluded["run"] = False              # unticked: run frames again
    f = int(picks[0])
    mm.frame = _far_frame(db, f)
    assert mm.search(mm.features.normalized[f].copy()).best_frame == f


def test_an_exclusion_that_leaves_nothing_or_names_a_missing_tag_is_one_line(mm, db):
    for tag in db.tag_names:
        mm.tuning.tag_excluded[tag] = True
    res = mm.search(mm.features.normalized[500].copy())
    assert res.best_frame >= 0                         # searched without the exclusion
    assert "'tag_excluded'" in mm.tag_error and "leaves no candidate frame" in mm.tag_error
    assert "\n" not in mm.tag_error
    for tag in db.tag_names:
        mm.tuning.tag_excluded[tag] = False
    mm.tuning.tag_excluded["sprint"] = True
    mm.search(mm.features.normalized[500].copy())
    assert "'tag_excluded.sprint'" in mm.tag_error and "has no range tagged 'sprint'" in mm.tag_error


def test_excluding_the_idle_tag_while_the_idle_set_is_active(mm, db):
    """The idle set is taken from the frames left after the exclusion: excluding ``idle`` empties it, which
    is reported, and the search keeps to the frames not excluded."""
    mm.stick_released_s = 10.0
    mm.tuning.tag_excluded["idle"] = True
    idle = db.tag_mask("idle")
    res = mm.search(mm.features.normalized[int(np.flatnonzero(idle)[5])].copy())
    assert not idle[res.frames].any()
    assert "'idle_set_enabled'" in mm.tag_error and "outside the excluded tags" in mm.tag_error
    assert "searching every frame not excluded" in mm.tag_error


def test_tag_exclusions_are_validated_and_reset():
    with pytest.raises(TuningError, match=r"'tag_excluded.run': expected true or false, got 1"):
        Tuning.from_dict({"tag_excluded": {"run": 1}})
    with pytest.raises(TuningError, match=r"'tag_excluded': expected an object of name -> true or false"):
        Tuning.from_dict({"tag_excluded": ["run"]})
    t = Tuning.from_dict({"tag_excluded": {"run": True, "mine": True}})
    assert t.tag_excluded["run"] and t.tag_excluded["mine"] and not t.tag_excluded["walk"]
    t.reset_group("search")
    assert not any(t.tag_excluded.values()) and "mine" in t.tag_excluded


def test_set_changes_one_entry_of_any_per_name_field():
    """What the studio's per-tag sliders and checkboxes call: one entry, checked; a bad one changes nothing."""
    t = Tuning()
    t.set("tag_bias", 2.5, channel="walk")
    t.set("tag_excluded", True, channel="crouch")
    t.set("feature_weights", 0.5, channel="hip_velocity")
    assert (t.tag_bias["walk"], t.tag_excluded["crouch"], t.feature_weights["hip_velocity"]) == (2.5, True, 0.5)
    before = t.to_dict()
    for args, message in ((("tag_bias", 9.0, "walk"), r"'tag_bias.walk': 9.0 is outside \[-5.0, 5.0\]"),
                          (("tag_excluded", 1.0, "walk"), r"'tag_excluded.walk': expected true or false"),
                          (("tag_bias", 1.0, "sprint"), r"'tag_bias': unknown tag 'sprint' \(tags: idle, "),
                          (("feature_weights", 1.0, "nope"), r"'feature_weights': unknown channel 'nope'"),
                          (("stick_deadzone", 0.3, "walk"), r"'stick_deadzone' has no channels")):
        with pytest.raises(TuningError, match=message):
            t.set(args[0], args[1], channel=args[2])
    assert t.to_dict() == before


def test_a_preset_loaded_later_keeps_the_database_tags(tmp_path):
    """The studio loads a preset into the tuning the controllers share, after they added their database's
    own tags: those entries stay (reset), so their slider and checkbox still set them, and the preset's
    values arrive."""
    t = Tuning()
    t.tag_bias.setdefault("dance", 0.0)            # what a controller on a database tagged "dance" adds
    t.tag_excluded.setdefault("dance", False)
    t.tag_excluded["dance"] = True
    t.feature_weights["head_velocity"] = 0.5        # a custom schema's channel
    preset = tmp_path / "p.json"
    preset.write_text('{"tag_excluded": {"walk": true}, "tag_bias": {"run": 1.5}}')
    shared = t
    t.assign(Tuning.load(preset))
    assert shared is t and t.tag_excluded["walk"] and t.tag_bias["run"] == 1.5
    assert t.tag_excluded["dance"] is False and t.tag_bias["dance"] == 0.0    # kept, reset
    assert t.feature_weights["head_velocity"] == 0.5 and t.tag_bias["crouch"] == 1.0
    t.set("tag_excluded", True, channel="dance")   # the checkbox still works
    t.set("tag_bias", -2.0, channel="dance")
    assert t.tag_excluded["dance"] and t.tag_bias["dance"] == -2.0
