"""The learned motion matching runtime: numpy networks vs torch, the controller, its snapshot, bone lengths."""

import numpy as np
import pytest

from lmm.controller import InputState
from lmm.data.build import load_or_build
from lmm.features import build_features
from lmm.learned import DEFAULT_WEIGHTS, LearnedMotionMatchingController, LMMNetworks
from lmm.pose_decoding import xform_xy_to_quat
from lmm.data.weights import WeightsError


@pytest.fixture(scope="module")
def dbf():
    db, _ = load_or_build()
    return db, build_features(db)


@pytest.fixture(scope="module")
def nets(dbf, tmp_path_factory):
    """The shipped networks when they fit the database, else a tiny freshly trained set."""
    db, features = dbf
    try:
        return LMMNetworks.load(DEFAULT_WEIGHTS, db, features)
    except WeightsError:
        pytest.importorskip("torch")
        from lmm.offline import training as T
        out = tmp_path_factory.mktemp("lmm-weights")
        r = T.Recipe(decompressor=T.StageSettings(20, 32, 2e-3), stepper=T.StageSettings(10, 8, 2e-3),
                     projector=T.StageSettings(10, 32, 2e-3), stepper_window=6, hidden=64, threads=1)
        T.train_pipeline(db, features, T.NETWORKS, r, out, frames=np.arange(3000), quiet=True)
        return LMMNetworks.load(out / "default.npz", db, features)


def test_numpy_matches_torch(nets):
    torch = pytest.importorskip("torch")
    from lmm.offline.networks import MLPSpec, NormalizedMLP
    from lmm.data.weights import load
    wf = load(nets.path)
    rng = np.random.default_rng(0)
    for name in ("decompressor", "stepper", "projector"):
        net = NormalizedMLP(MLPSpec.from_dict(wf.spec(name)))
        net.load_arrays(wf.arrays, name)
        mlp = getattr(nets, name)
        x = (rng.normal(size=(64, mlp.n_in)) * 1.5).astype(np.float32)
        with torch.no_grad():
            ref = net(torch.from_numpy(x)).numpy()
        assert np.max(np.abs(mlp(x) - ref)) < 1e-4, name
        assert np.max(np.abs(mlp(x[0]) - ref[0])) < 1e-4, name


def test_fast_quaternion_decode_matches_gram_schmidt(dbf):
    from lmm import quat
    db, _ = dbf
    rot = db.rotations[::97, 1:].astype(np.float64)
    xy = quat.to_xform_xy(rot) + np.random.default_rng(1).normal(scale=0.1, size=rot.shape[:-1] + (3, 2))
    ref = quat.from_xform_xy(xy)
    got = np.stack([xform_xy_to_quat(x) for x in xy])
    assert np.max(np.abs(np.abs(np.sum(ref * got, -1)) - 1.0)) < 1e-9


def test_wrong_database_is_refused(dbf, nets):
    db, features = dbf
    import copy
    other = copy.copy(db)
    other.key = "0" * 64
    with pytest.raises(WeightsError, match="trained on another database"):
        LMMNetworks.load(nets.path, other, features)


def test_controller_runs_and_fills_the_snapshot(dbf, nets):
    db, features = dbf
    ctrl = LearnedMotionMatchingController(db, features, networks=nets)
    assert ctrl.name == "lmm"
    searched = transitioned = 0
    X = ctrl.features.normalized.astype(np.float64)
    for i in range(240):
        inp = InputState(left_x=np.sin(i / 40.0), left_y=1.0 if i < 160 else 0.0)
        pose, snap = ctrl.step(inp, 1.0 / 60.0)
        searched += snap.searched
        transitioned += snap.transitioned
        if snap.searched:   # the frame the projector "chose": the exact nearest frame to its features
            costs = np.sum((X - snap.projected_features.astype(np.float64)) ** 2, axis=1)
            assert costs[snap.projected_frame] == pytest.approx(costs.min(), rel=1e-5, abs=1e-6)
        else:
            assert snap.projected_frame == -1
        assert np.all(np.isfinite(pose.global_positions))
        assert snap.latent.shape == (32,)
        assert snap.controller == "lmm"
    assert searched >= 20  # every 0.1 s
    assert snap.projected_features.shape == (features.n_dims,)
    assert 0 <= snap.nn_frame < db.n_frames
    # the exact search's answer for the same query is reported beside the projection
    assert np.isfinite(snap.nn_cost) and np.isfinite(snap.projected_cost)
    assert snap.nn_cost == pytest.approx(float(np.sum((snap.query - features.normalized[snap.nn_frame]) ** 2)),
                                         rel=1e-4, abs=1e-5) or not snap.searched
    assert "advance" in snap.timings_us
    split = ctrl._run_decompressor_tick.nbytes      # the per-tick copy of the decompressor's last layer
    assert split == nets.decompressor._single_plan()[3].nbytes
    want = {"decompressor": nets.decompressor.nbytes() + split, "stepper": nets.stepper.nbytes(),
            "projector": nets.projector.nbytes()}
    idle = ctrl.idle_states()
    if idle is not None:     # the idle set: frames, network states and their normalised features
        want["idle_set"] = idle[0].nbytes + idle[1].nbytes + len(idle[0]) * features.n_dims * 4
    assert ctrl.memory_bytes() == want


def test_without_the_debug_comparison_only_the_projected_frame_is_searched(dbf, nets):
    db, features = dbf
    ctrl = LearnedMotionMatchingController(db, features, networks=nets, compare_with_search=False)
    snaps = [ctrl.step(InputState(left_y=1.0), 1.0 / 60.0)[1] for _ in range(30)]
    assert any(s.searched for s in snaps)
    assert all("nn_search" not in s.timings_us and s.nn_frame == snaps[0].nn_frame for s in snaps)
    assert all((s.projected_frame >= 0) == s.searched == ("projected_frame_search" in s.timings_us) for s in snaps)


def _headless_lmm_run(db, features, nets, seconds, patch=None):
    """``seconds`` of builtin:random:1 through a headless LMM (no debug comparison), as ``run`` steps it:
    (metrics, snapshots, poses' global positions, per tick whether the state took a projection: the
    base controller's jump, seen by wrapping ``_search``)."""
    from lmm.data.inputs import open_input
    from lmm.runner import run_headless

    ctrl = LearnedMotionMatchingController(db, features, networks=nets, compare_with_search=False)
    for name, fn in (patch or {}).items():
        setattr(ctrl, name, fn.__get__(ctrl))
    took, search = {}, ctrl._search

    def spy(query, forced):
        outcome = search(query, forced)
        took[ctrl.tick + 1] = outcome.target is not None
        return outcome
    ctrl._search = spy
    snaps, poses = [], []
    metrics = run_headless(ctrl, open_input("builtin:random:1", seconds), seconds,
                           on_step=lambda pose, snap: (snaps.append(snap), poses.append(pose.global_positions.copy())))
    return metrics, snaps, np.array(poses), took


def test_headless_lmm_reports_the_projected_frame_as_its_match_and_projector_jumps_as_transitions(dbf, nets):
    """matched_frame is the last taken projection's frame advanced by the frames played since (kept in its
    range), transitioned a taken projection that does not continue it: counted here from the snapshots'
    projected frames and the state's jumps, without the controller's own bookkeeping."""
    from lmm.mm import default_start_frame

    db, features = dbf
    metrics, snaps, _, took = _headless_lmm_run(db, features, nets, 20.0)
    fps, tol = db.fps, LearnedMotionMatchingController.CONTINUATION_TOLERANCE_S * db.fps
    frame, since = default_start_frame(db), 0   # where run_headless resets it
    jumps = 0
    for snap in snaps:
        since += 1
        if snap.searched and took[snap.tick]:
            p = snap.projected_frame
            cont = min(frame + round(since / 60.0 * fps), db.range_stop_of(frame) - 1)
            jumps += db.range_index(p) != db.range_index(frame) or abs(p - cont) > tol
            frame, since = p, 0
        assert snap.matched_frame == min(frame + round(since / 60.0 * fps), db.range_stop_of(frame) - 1)
    assert sum(took.values()) > jumps > 10          # not every taken projection is a jump
    assert metrics["transitions"] == jumps == sum(s.transitioned for s in snaps)
    assert len({s.matched_frame for s in snaps}) > 50
    shares = [v for k, v in metrics.items() if k.startswith("tag_share_")]
    assert any(0.0 < v < 1.0 for v in shares), shares


def test_the_lmm_pose_does_not_read_its_matched_frame(dbf, nets):
    """With the matched frame's search and bookkeeping replaced by nothing (every projection "nearest" to
    frame 0, no match taken), the same 10 s gives the same poses bit for bit."""
    db, features = dbf
    _, snaps, poses, _ = _headless_lmm_run(db, features, nets, 10.0)
    off = {"exact_nearest": lambda self, q, top_k=None: (0, 0.0, None), "_take_match": lambda self, frame: None}
    _, snaps_off, poses_off, _ = _headless_lmm_run(db, features, nets, 10.0, off)
    assert sum(s.transitioned for s in snaps) > 10 and not any(s.transitioned for s in snaps_off)
    assert np.array_equal(poses, poses_off)


def test_the_motion_does_not_depend_on_the_debug_comparison(dbf, nets):
    """Ground calibration follows the take the state was projected from, looked up whether or not the
    debug nearest-neighbour comparison runs: headless runs and the studio show the same motion."""
    from lmm.data.inputs import open_input

    db, features = dbf
    log = open_input("builtin:random:1", 12.0)
    runs = {}
    for compare in (True, False):
        ctrl = LearnedMotionMatchingController(db, features, networks=nets, compare_with_search=compare)
        poses, calib = [], set()
        for i in range(600):
            pose, _ = ctrl.step(log.at(i / 60.0), 1.0 / 60.0)
            poses.append(pose.global_positions.copy())
            calib.add(ctrl._calibration_frame())
        runs[compare] = (np.array(poses), calib)
    assert np.array_equal(runs[True][0], runs[False][0])
    assert runs[True][1] == runs[False][1] and len(runs[False][1]) > 3     # it follows the jumps


def test_lazy_query_and_features_are_the_ticks_values(dbf, nets):
    """The learned state changes every tick: a snapshot's query, trajectory and current features (made
    from a copy of the state when not searching) read late are the bytes read at once, and on a tick
    that searches the current features are the state's, converted as the controller does."""
    from lmm.data.inputs import open_input

    db, features = dbf
    log = open_input("builtin:random:1", 3.0)
    fields = ("trajectory_positions", "trajectory_rotations", "query", "current_features")
    runs = []
    for late in (False, True):
        ctrl = LearnedMotionMatchingController(db, features, networks=nets, compare_with_search=False)
        snaps = []
        for i in range(120):
            snap = ctrl.step(log.at(i / 60.0), 1.0 / 60.0)[1]
            if not late:
                [getattr(snap, f) for f in fields]
                want = ctrl.features.normalize(ctrl.nets.from_network_space(ctrl.state[:ctrl.nets.n_features]))
                assert snap.current_features.tobytes() == want.tobytes()
            snaps.append(snap)
        runs.append(snaps)
    assert any(s.searched for s in runs[1]) and not all(s.searched for s in runs[1])
    for now, later in zip(*runs):
        for f in fields:
            a, b = getattr(now, f), getattr(later, f)
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), f
        assert now.current_cost == later.current_cost


def test_calibration_lookup_finds_the_take_of_a_database_frame(dbf, nets):
    db, features = dbf
    ctrl = LearnedMotionMatchingController(db, features, networks=nets, compare_with_search=False)
    stride = ctrl.CALIBRATION_STRIDE
    for frame in (0, stride * 7, stride * 400, (db.n_frames - 1) // stride * stride):
        assert ctrl._calibration_lookup(features.normalized[frame]) == frame
    # a frame between two candidates: the nearest candidate, by brute force over every stride-th frame (often
    # of another range of the take, or another take: the floor of takes of one session is shared)
    X = features.normalized
    for frame in range(stride * 300 + stride // 2, db.n_frames, stride * 97):
        got = ctrl._calibration_lookup(X[frame])
        d = X[::stride] - X[frame]
        assert got % stride == 0 and got == int(np.argmin(np.einsum("ij,ij->i", d, d))) * stride


@pytest.mark.slow
def test_ten_minutes_of_random_input_stay_sane(dbf, nets):
    """10 minutes of builtin:random:1: no NaN, no pose explosion, bone lengths within 1 cm."""
    from lmm.data.inputs import open_input
    db, features = dbf
    seconds = 600.0
    log = open_input("builtin:random:1", seconds)
    ctrl = LearnedMotionMatchingController(db, features, networks=nets, compare_with_search=False)
    ref = np.linalg.norm(db.positions[0, 2:].astype(np.float64), axis=-1)
    parents = db.parents[2:]
    dt = 1.0 / 60.0
    worst = 0.0
    for i in range(int(seconds / dt)):
        pose, snap = ctrl.step(log.at(i * dt), dt)
        g = pose.global_positions.astype(np.float64)
        if not np.all(np.isfinite(g)) or not np.all(np.isfinite(snap.latent)):
            pytest.fail(f"non-finite pose at tick {i}")
        lengths = np.linalg.norm(g[2:] - g[parents], axis=-1)
        worst = max(worst, float(np.max(np.abs(lengths - ref))))
        assert np.linalg.norm(g[1] - g[0]) < 2.0, f"hips 2 m from the root at tick {i}"
    assert worst < 0.01, f"bone length off by {worst * 100:.2f} cm"


def _idle_controller(db, features, nets):
    """A learned controller with an idle set (the test is skipped without idle frames or a compressor)."""
    from pathlib import Path

    if not db.tag_mask("idle").any():
        pytest.skip("the database has no idle range")
    if not Path(nets.path).with_name("compressor.npz").is_file():
        pytest.skip("no compressor beside the networks")
    return LearnedMotionMatchingController(db, features, networks=nets)


def test_idle_set_jumps_the_state_to_an_idle_frame(dbf, nets):
    """Stick released past idle_delay_s: the learned controller's next search is an exact search over the
    idle-tagged frames and its state jumps to that frame's features and compressor latent (the projector
    cannot keep to a subset). Without a compressor beside the weights the snapshot says why."""
    db, features = dbf
    ctrl = _idle_controller(db, features, nets)
    ctrl.tuning.search_interval_s = 0.05
    for _ in range(30):
        ctrl.step(InputState(left_y=1.0), 1.0 / 60.0)
    jumped = None
    for _ in range(120):
        _, snap = ctrl.step(InputState(), 1.0 / 60.0)
        if snap.searched and ctrl.idle_set_active():
            jumped = snap
            break
    assert jumped is not None and "idle" in db.tags_of(jumped.projected_frame) and jumped.search_note == ""
    frames, states = ctrl.idle_states()
    k = int(np.nonzero(frames == jumped.projected_frame)[0][0])
    # the state is the idle frame's, advanced by the stepper since (one tick at most)
    assert np.abs(ctrl.state - states[k]).max() < 0.5
    ctrl.tuning.idle_set_enabled = False
    assert not ctrl.idle_set_active()


@pytest.mark.parametrize("follow", [True, False])
def test_in_the_idle_set_the_state_follows_the_idle_take(dbf, nets, follow):
    """Between jumps in the idle set each search sets the state to the idle take's frame the playing one has
    reached (its features and compressor latent, exactly), a continuation: not a projector jump, so the
    snapshot says no transition. With ``idle_follow_take`` off the stepper runs on from the jump alone."""
    db, features = dbf
    ctrl = _idle_controller(db, features, nets)
    ctrl.tuning.idle_follow_take = follow
    frames, states = ctrl.idle_states()
    followed = []
    take_match = ctrl._take_match

    def watch(frame):
        expected = ctrl._source_frame()       # where the matched frame has got to, before this search
        k = np.searchsorted(frames, frame)
        on_take = k < len(frames) and frames[k] == frame and np.array_equal(ctrl.state, states[k])
        take_match(frame)
        followed.append((frame == expected and on_take, ctrl._jumped))

    ctrl._take_match = watch
    for _ in range(30):
        ctrl.step(InputState(left_y=1.0), 1.0 / 60.0)
    followed.clear()
    transitions = 0
    for _ in range(240):                      # 4 s standing: the idle set from 0.75 s on
        _, snap = ctrl.step(InputState(), 1.0 / 60.0)
        transitions += bool(snap.transitioned)
    continuations = [f for f in followed if f[0]]
    if follow:
        assert len(continuations) >= 20, followed     # most of the 0.1 s searches of the last 3 s
        assert not any(jumped for _, jumped in continuations)
        assert transitions == sum(jumped for _, jumped in followed)
    else:
        assert not continuations


def test_idle_set_without_compressor_is_a_note(dbf, nets, tmp_path):
    import shutil

    db, features = dbf
    if not db.tag_mask("idle").any():
        pytest.skip("the database has no idle range")
    shutil.copy(nets.path, tmp_path / "default.npz")     # no compressor.npz beside this copy
    lonely = LMMNetworks.load(tmp_path / "default.npz", db, features)
    ctrl = LearnedMotionMatchingController(db, features, networks=lonely)
    snap = None
    for _ in range(90):
        _, snap = ctrl.step(InputState(), 1.0 / 60.0)
    assert ctrl.idle_states() is None and "compressor.npz" in snap.search_note
