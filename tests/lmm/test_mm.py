"""The motion matching controller: snapshot contents, tunables acting on the next step, long-run
stability, determinism."""
import dataclasses

import numpy as np
import pytest

from lmm.controller import DebugSnapshot, InputState
from lmm.data.inputs import builtin
from lmm.mm import MotionMatchingController
from lmm.runner import run_headless
from lmm.tuning import Tuning

DT = 1 / 60


def test_snapshot_is_complete(db, features):
    c = MotionMatchingController(db, features)
    log = builtin("zigzag", 3.0)
    snaps = [c.step(log.at(i * DT), DT)[1] for i in range(120)]
    s = snaps[-1]
    for f in dataclasses.fields(DebugSnapshot):
        if f.name in ("latent", "projected_features", "matched_latent", "nn_frame", "nn_cost", "projected_cost",
                      "projected_frame"):
            continue  # learned motion matching extras
        v = getattr(s, f.name)
        assert v is not None, f.name
        if isinstance(v, np.ndarray) and v.dtype.kind == "f":
            assert np.isfinite(v).all(), f.name
    T = len(c.traj_offsets)
    assert s.trajectory_positions.shape == (T, 3) and s.trajectory_rotations.shape == (T, 4)
    assert list(s.trajectory_offsets) == [20, 40, 60]
    assert s.query.shape == s.current_features.shape == s.matched_features.shape == (features.n_dims,)
    assert s.pose.global_positions.shape == (db.n_bones, 3) and s.matched_pose_positions.shape == (db.n_bones, 3)
    assert s.candidates.channel_costs.shape == (len(s.candidates.frames), len(features.layout))
    assert s.candidates.channel_names == features.names
    assert {"search", "total", "pose"} <= set().union(*(x.timings_us for x in snaps))
    assert sum(x.searched for x in snaps) >= 18 and any(x.transitioned for x in snaps)
    assert any(x.forced_search for x in snaps)  # zigzag reverses sharply
    searched = [x for x in snaps if x.searched]
    assert all(x.candidates.frames[0] == x.best_frame if hasattr(x, "best_frame") else True for x in searched)
    assert np.isfinite(s.best_cost) and np.isfinite(s.current_cost)


def test_lazy_snapshot_features_are_the_ticks_values(db, features):
    """current_features, current_cost and matched_features are worked out when read, with the tick's own
    feature scaling: a weight change after the tick (or reading late) does not change them."""
    c = MotionMatchingController(db, features)
    features = c.features                  # the controller's own copy (its weights are its own)
    log = builtin("zigzag", 3.0)
    snaps = [c.step(log.at(i * DT), DT)[1] for i in range(90)]
    early = snaps[60]
    want_cur = features.normalize(features.raw[early.matched_frame])
    want_cost = float(np.sum((early.query - want_cur) ** 2, dtype=np.float32))
    want_matched = features.normalized[early.matched_frame].copy()
    c.tuning.feature_weights = {features.layout[0].name: 7.0}     # rescales on the next step
    later = c.step(log.at(90 * DT), DT)[1]
    assert not np.array_equal(features.normalized[early.matched_frame], want_matched)
    assert early.current_features.tobytes() == want_cur.tobytes()
    assert early.current_cost == pytest.approx(want_cost, rel=1e-6)
    assert early.matched_features.tobytes() == want_matched.tobytes()
    assert early.current_features is early.current_features                # computed once
    assert np.isfinite(later.current_cost) and later.current_features.dtype == np.float32


def test_lazy_trajectory_and_query_are_the_ticks_values(db, features):
    """On a tick that does not search, the trajectory and the query are worked out when read (the
    simulation's and desired arrays on every tick): read at once or 90 ticks (and a feature-weight
    change) later, they are the same bytes; on a tick that searches the query is made at once."""
    log = builtin("zigzag", 3.0)
    fields = ("trajectory_positions", "trajectory_rotations", "query", "simulation_position", "simulation_rotation",
              "simulation_velocity", "desired_velocity", "desired_rotation")
    runs = []
    for late in (False, True):
        c = MotionMatchingController(db, features)
        snaps = []
        for i in range(90):
            snap = c.step(log.at(i * DT), DT)[1]
            if not late:
                [getattr(snap, f) for f in fields]
                assert np.array_equal(snap.desired_velocity, c.desired_velocity)
                assert np.array_equal(snap.simulation_position, c.sim.position)
            snaps.append(snap)
        if late:
            c.tuning.feature_weights = {c.features.layout[0].name: 7.0}
            c.step(log.at(90 * DT), DT)
        runs.append(snaps)
    searched = [s.searched for s in runs[1]]
    assert any(searched) and not all(searched)
    for now, later in zip(*runs):
        if later.searched:
            assert not callable(later.__dict__["_lazy_query"])
        else:
            assert callable(later.__dict__["_lazy_query"])
        for f in fields:
            a, b = getattr(now, f), getattr(later, f)
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), f
        assert now.current_cost == later.current_cost


def _pair(db, features, warm_s=2.2, source="zigzag", until=None):
    """Two controllers in lockstep after ``warm_s`` seconds of the same input (and then until
    ``until(controller)`` holds)."""
    out = []
    log = builtin(source, 30.0)
    for _ in range(2):
        c = MotionMatchingController(db, features, Tuning())
        i = 0
        while i < int(warm_s * 60) or (until is not None and not until(c) and i < 1500):
            c.step(log.at(i * DT), DT)
            i += 1
        out.append(c)
    return out, log, i


def _diverges(a, b, inp, prepare=None):
    if prepare:
        prepare(a)
        prepare(b)
    pa, sa = a.step(inp, DT)
    pb, sb = b.step(inp, DT)
    fields = ("simulation_position", "simulation_rotation", "desired_velocity", "desired_rotation", "query",
              "trajectory_positions")
    differs = {f for f in fields if not np.array_equal(getattr(sa, f), getattr(sb, f))}
    if not np.array_equal(pa.global_positions, pb.global_positions):
        differs.add("pose")
    if not np.array_equal(sa.foot_locked, sb.foot_locked):
        differs.add("foot_locked")
    if not (np.array_equal(sa.candidates.frames, sb.candidates.frames)
            and np.array_equal(sa.candidates.costs, sb.candidates.costs)):
        differs.add("candidates")
    return differs


def _force_search(c):
    c._needs_search = True


def _locked(c):
    return bool(c.foot_lock.locked.any())


# group -> list of (field changes, expected differing outputs, input, prepare)
PARTIAL = InputState(0.3, 0.4, 0.0, 0.0, False, False, 0.0)
CASES = {
    "simulation": [({"simulation_velocity_halflife_s": 0.05}, {"simulation_position", "trajectory_positions"}),
                   ({"simulation_rotation_halflife_s": 0.05}, {"simulation_rotation"}),
                   ({"stick_deadzone": 0.45}, {"desired_velocity"})],
    "speeds": [({"run_forward_speed_m_s": 2.0, "run_sideways_speed_m_s": 1.0, "run_backwards_speed_m_s": 0.5},
                {"desired_velocity"})],
    "inertialization": [({"inertialization_halflife_s": 0.25}, {"pose"})],
    "features": [({"feature_weights": {"trajectory_position": 3.0}}, {"query"})],
    "search": [({"transition_cost": 2.0}, {"candidates"}), ({"exclude_current_window_frames": 0}, {"candidates"}),
               ({"top_k": 3}, {"candidates"})],
    "sync": [({"adjustment_position_halflife_s": 0.9}, {"pose"}), ({"clamp_max_distance_m": 0.01}, {"pose"}),
             ({"adjustment_enabled": False, "clamping_enabled": False}, {"pose"})],
    "ik": [({"ik_enabled": False}, {"pose"}), ({"ik_unlock_radius_m": 0.0}, {"pose", "foot_locked"}, _locked)],
}


@pytest.mark.parametrize("group", sorted(CASES))
def test_each_tunable_group_changes_the_next_step(db, features, group):
    assert group in Tuning.groups()
    for change, expected, *until in CASES[group]:
        # a few starting points: some effects need a state that has them (a locked foot, a candidate
        # near the playing frame); one demonstration per tunable is the claim
        for warm_s, source in ((2.2, "zigzag"), (3.0, "circle"), (4.5, "random:3"), (6.0, "stop-and-go")):
            (a, b), log, tick = _pair(db, features, warm_s, source, until=until[0] if until else None)
            assert not _diverges(a, b, log.at(tick * DT))  # the pair agrees before the change
            delta = change(b) if callable(change) else change
            for k, v in delta.items():
                if isinstance(v, dict):
                    getattr(b.tuning, k).update(v)
                else:
                    setattr(b.tuning, k, v)
            inp = PARTIAL if group in ("simulation", "speeds") else log.at((tick + 1) * DT)
            got = _diverges(a, b, inp, prepare=_force_search)
            if expected & got:
                break
        assert expected & got, f"{group} {delta}: only {got} changed"


def test_range_end_exclusion_acts_on_the_next_search(db, features):
    """Playing 60 frames before the end of a range: widening the excluded end to 100 frames stops the
    playing frame from continuing at the very next search."""
    stop = int(db.range_stops[0])
    pair = [MotionMatchingController(db, features) for _ in range(2)]
    steady = InputState(0.0, 0.0, 0.0, 0.0, False, False, 0.0)
    for c in pair:
        c.reset(frame=stop - 60)
        c.tuning.search_interval_s = 10.0  # no search on its own in between
        c._needs_search = False             # (nor the one after a reset)
        for _ in range(2):
            c.step(steady, DT)
    a, b = pair
    b.tuning.exclude_range_end_frames = 100
    for c in pair:
        c._needs_search = True
    sa, sb = a.step(steady, DT)[1], b.step(steady, DT)[1]
    assert sa.searched and sb.searched
    assert np.isfinite(a.last_search.continuing_cost) and np.isnan(b.last_search.continuing_cost)
    assert stop - 60 + 2 not in sb.candidates.frames


def test_search_interval_and_forced_search(db, features):
    t = Tuning()
    t.search_interval_s = 0.5
    c = MotionMatchingController(db, features, t)
    steady = InputState(0.0, 1.0, 0.0, 0.0, False, False, 0.0)
    searched = [c.step(steady, DT)[1].searched for _ in range(120)]
    assert 4 <= sum(searched) <= 6
    t.search_interval_s = 0.0  # read on the next tick
    assert all(c.step(steady, DT)[1].searched for _ in range(5))
    t.search_interval_s = 1.0
    c.step(steady, DT)
    back = InputState(0.0, -1.0, 0.0, 0.0, False, False, 0.0)
    snaps = [c.step(back, DT)[1] for _ in range(10)]
    assert any(s.forced_search for s in snaps)


def test_accelerated_and_brute_force_controllers_agree(db, features):
    a = MotionMatchingController(db, features)
    t = Tuning()
    t.accelerated_search = False
    b = MotionMatchingController(db, features, t)
    log = builtin("random:2", 8.0)
    for i in range(480):
        pa, sa = a.step(log.at(i * DT), DT)
        pb, sb = b.step(log.at(i * DT), DT)
        assert sa.matched_frame == sb.matched_frame
        assert np.array_equal(pa.global_positions, pb.global_positions)


def test_runs_are_deterministic(db, features):
    def run():
        poses = []
        run_headless(MotionMatchingController(db, features), builtin("stop-and-go", 5.0), 5.0,
                     on_step=lambda p, s: poses.append(p.global_positions.copy()))
        return np.stack(poses)
    assert np.array_equal(run(), run())


@pytest.mark.slow
def test_ten_minutes_of_random_input(db, features):
    t = Tuning()
    c = MotionMatchingController(db, features, t)
    worst = [0.0]

    def check(pose, snap):
        assert np.isfinite(pose.global_positions).all() and np.isfinite(pose.global_rotations).all()
        worst[0] = max(worst[0], float(np.linalg.norm(pose.global_positions[0] - snap.simulation_position)))

    m = run_headless(c, builtin("random:1", 600.0), 600.0, on_step=check)
    assert m["ticks"] == 36000 and m["non_finite_ticks"] == 0
    assert worst[0] <= t.clamp_max_distance_m + 0.01
    assert m["trajectory_error_max_m"] <= t.clamp_max_distance_m + 0.01
    assert 0.0 < m["foot_skating_cm_s"] < 30.0
    assert m["transitions_per_s"] > 0.5
    print(f"\n10 min random:1: max root-sim {worst[0]:.4f} m, skating {m['foot_skating_cm_s']:.2f} cm/s, "
          f"{m['transitions_per_s']:.2f} transitions/s")


def test_matched_latent_comes_from_the_attached_table(db, features):
    c = MotionMatchingController(db, features)
    assert c.step(InputState(left_y=1.0), DT)[1].matched_latent is None       # no table: no latent
    table = np.arange(db.n_frames * 3, dtype=np.float32).reshape(db.n_frames, 3)
    c.set_latent_table(table)
    for _ in range(40):
        _, s = c.step(InputState(left_y=1.0), DT)
        assert s.matched_latent.tolist() == table[s.matched_frame].tolist()
    c.set_latent_table(None)
    assert c.step(InputState(), DT)[1].matched_latent is None
    with pytest.raises(ValueError, match="one row per database frame"):
        c.set_latent_table(table[:10])


def test_memory_bytes_counts_pose_features_and_index(db, features):
    from lmm.search import SearchIndex

    c = MotionMatchingController(db, features)
    before = c.memory_bytes()
    assert before == {"pose data (Y)": db.pose_bytes(), "features (X)": c.features.normalized.nbytes}
    c.step(InputState(), DT)      # the first tick searches and builds the index
    parts = c.memory_bytes()
    native = c.index._native          # the compiled filter (its top boxes), when the build made one
    assert parts["search index"] == SearchIndex(c.features.normalized).nbytes() + (
        native.nbytes() if native else 0) > 0
    # the index's own arrays only: the features it searches count once, unless the index had to copy
    # them (a frame count that is not a whole number of blocks is padded)
    idx = c.index
    copied = sum(getattr(idx, n).nbytes for n in ("X", "rows")
                 if not np.shares_memory(getattr(idx, n), c.features.normalized))
    assert parts["search index"] - copied < c.features.normalized.nbytes


def test_ground_calibration_shifts_each_take_to_foot_height_without_popping(db, features):
    from lmm.ground import range_contact_heights

    toes = [db.bone("left_toe"), db.bone("right_toe")]
    heights = range_contact_heights(db, toes)
    assert np.isfinite(heights).all() and np.ptp(heights) > 0.01  # the shipped takes differ in calibration
    log = builtin("random:1", 8.0)
    runs = {}
    for on in (True, False):
        c = MotionMatchingController(db, features, Tuning(ik_enabled=False, ik_ground_calibration=on))
        poses, targets = [], []
        for i in range(480):
            pose, snap = c.step(log.at(i * DT), DT)
            poses.append(pose.global_positions.astype(np.float64))
            targets.append(c.tuning.ik_foot_height_m - heights[db.range_index(snap.matched_frame)])
        runs[on] = (np.array(poses), np.array(targets), c)
    on, off = runs[True][0], runs[False][0]
    shift = on[:, :, 1] - off[:, :, 1]
    # a rigid vertical shift of the whole pose (the same motion otherwise) ...
    assert np.allclose(on[:, :, [0, 2]], off[:, :, [0, 2]], atol=1e-5)
    assert np.allclose(shift[:, 1:], shift[:, 1:2], atol=1e-5)
    # ... that follows the playing take's target, and never pops at a jump between takes
    targets = runs[True][1]
    assert len(np.unique(np.round(targets, 4))) > 1 and np.abs(shift).max() > 0.005
    assert np.abs(np.diff(shift[:, 1])).max() < 0.004
    assert np.abs(shift[-1, 1] - targets[-1]) < 0.01


def test_the_ranked_candidates_are_the_ticks_top_k_searched_when_read(db, features):
    """A tick searches for the best frame only; the snapshot's ranked top K is searched when first read,
    from what the tick searched with: the same frames, totals, biases and channel costs as a ranked
    search made at the tick, read right away, after later searches, and after a weight change that
    rebuilt the index (then by brute force). Ticks between two searches share one ranking."""
    c = MotionMatchingController(db, features)
    c.reset()
    log = builtin("zigzag", 10.0)
    eager, tick_search = [], c._search

    def spy(query, forced):
        eager.append(c.search(query, hint=c.search_hint()))     # the ranked top K (the tuning's), no side effects
        return tick_search(query, forced)

    c._search = spy
    snaps = [c.step(log.at(i * DT), DT)[1] for i in range(240)]
    searched = [s for s in snaps if s.searched]
    assert len(searched) == len(eager) >= 20
    first_read = searched[1::2]                 # read now; the others after the weight change below
    for s, e in zip(searched[1::2], eager[1::2]):
        _assert_same_ranking(s.candidates, e, c.tuning.top_k)
    for a, b in zip(snaps, snaps[1:]):
        if not b.searched:
            assert b.candidates is a.candidates
    assert all(s.best_cost == s.candidates.costs[0] for s in first_read)
    old_norm = c.features.normalized
    c.tuning.feature_weights["trajectory_position"] = 3.0
    for i in range(240, 300):
        c.step(log.at(i * DT), DT)
    assert c.features.normalized is not old_norm and c.index.features_norm is not old_norm
    for s, e in zip(searched[::2], eager[::2]):
        _assert_same_ranking(s.candidates, e, c.tuning.top_k)


def _assert_same_ranking(cands, res, k):
    assert len(cands.frames) == min(k, len(res.frames)) == len(res.frames)
    assert np.array_equal(cands.frames, res.frames) and np.array_equal(cands.costs, res.costs)
    assert np.array_equal(cands.bias, res.bias) and np.array_equal(cands.channel_costs, res.channel_costs)
