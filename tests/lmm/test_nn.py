"""The numpy network runtime's batch-1 path (normalisation and biases folded into the matrices, one
``np.dot`` per layer) agrees with the plain evaluation within float32 rounding: the sums are reordered,
so the last bits differ (1e-5 of the output's scale at most), and a folding mistake (a wrong row, a
missing bias or scale) is far outside that."""
import numpy as np
import pytest

from lmm.learned import DEFAULT_WEIGHTS
from lmm.nn import MLP


def plain_params(arrays: dict, name: str, activation: str = "relu", skip: bool = False) -> dict:
    """A network's parameters as a weights file holds them (before any folding)."""
    n = sum(1 for k in arrays if k.startswith(f"{name}.W"))
    return {"weights": [arrays[f"{name}.W{i}"] for i in range(n)], "biases": [arrays[f"{name}.b{i}"] for i in range(n)],
            "activation": activation, "skip": skip, "norm": tuple(arrays[f"{name}.{k}"] for k in
                                                                   ("in_mean", "in_std", "out_mean", "out_std"))}


def make_mlp(plain: dict) -> MLP:
    """An MLP from ``plain`` (see :func:`plain_params`), which it keeps as ``plain`` for reference_mlp."""
    mlp = MLP(plain["weights"], plain["biases"], plain["activation"], *plain["norm"], skip=plain["skip"])
    mlp.plain = plain
    return mlp


def reference_mlp(mlp: MLP, x: np.ndarray) -> np.ndarray:
    """The evaluation as written before the folded layers, on the network's unfolded parameters
    (``mlp.plain``): (1, D) rows, normalise, matmul, bias, activation, scale."""
    p = mlp.plain
    in_mean, in_std, out_mean, out_std = (np.asarray(v, np.float32) for v in p["norm"])
    weights = [np.asarray(w, np.float32) for w in p["weights"]]
    h = np.empty((1, mlp.n_in), np.float32)
    np.subtract(x.reshape(1, -1), in_mean, out=h)
    np.multiply(h, (1.0 / in_std).astype(np.float32), out=h)
    for i, (w, b) in enumerate(zip(weights, p["biases"])):
        nxt = np.empty((1, w.shape[1]), np.float32)
        np.matmul(h, w, out=nxt)
        nxt += np.asarray(b, np.float32)
        if i < len(weights) - 1:
            if p["activation"] == "relu":
                np.maximum(nxt, 0.0, out=nxt)
            else:
                neg = np.minimum(nxt, 0.0)
                np.expm1(neg, out=neg)
                np.maximum(nxt, 0.0, out=nxt)
                nxt += neg
        h = nxt
    y = h * out_std
    y += out_mean
    if p["skip"]:
        y[:, :x.shape[0]] += x
    return y[0]


def close(got, ref) -> bool:
    """Within float32 rounding of reordered sums: 1e-5 of the output's largest magnitude."""
    scale = max(1.0, float(np.abs(ref).max()))
    return got.shape == ref.shape and float(np.abs(got.astype(np.float64) - ref).max()) <= 1e-5 * scale


def same_bits(a, b) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a.view(np.uint32), b.view(np.uint32))


@pytest.fixture(scope="module")
def shipped():
    arrays = dict(np.load(DEFAULT_WEIGHTS))
    return {n: make_mlp(plain_params(arrays, n, skip=n == "projector")) for n in ("decompressor", "stepper", "projector")}


@pytest.mark.parametrize("name", ["decompressor", "stepper", "projector"])
def test_shipped_networks_batch1_matches_the_plain_evaluation(shipped, name):
    mlp = shipped[name]
    rng = np.random.default_rng(7)
    out = np.empty(mlp.n_out, np.float32)
    for t in range(200):
        x = (rng.standard_normal(mlp.n_in) * rng.uniform(0.1, 3.0)).astype(np.float32 if t % 3 else np.float64)
        ref = reference_mlp(mlp, x)
        got = mlp(x)
        assert got.dtype == np.float32 and close(got, ref), f"{name}: input {t} differs by {np.max(np.abs(got - ref))}"
        assert mlp(x, out=out) is out and same_bits(out, got)  # the same bits into ``out``
        assert close(mlp(x[None])[0], ref)  # the batched path: the same folded layers, summed as a batch
    # a fresh array per call when no ``out`` is given (callers keep the states they get)
    assert mlp(x) is not mlp(x)


def test_elu_float64_out_and_aliased_skip():
    rng = np.random.default_rng(3)
    ws = [rng.standard_normal((5, 16)), rng.standard_normal((16, 16)), rng.standard_normal((16, 7))]
    bs = [rng.standard_normal(16), rng.standard_normal(16), rng.standard_normal(7)]
    norm = (rng.standard_normal(5), rng.uniform(0.5, 2, 5), rng.standard_normal(7), rng.uniform(0.5, 2, 7))
    for act, skip in (("elu", False), ("relu", True), ("elu", True)):
        mlp = make_mlp({"weights": ws, "biases": bs, "activation": act, "skip": skip, "norm": norm})
        x = rng.standard_normal(5).astype(np.float32)
        ref = reference_mlp(mlp, x)
        got = mlp(x)
        assert close(got, ref)
        out64 = np.zeros(7)
        mlp(x, out=out64)
        assert np.array_equal(out64, got.astype(np.float64))
        if skip:  # the output overwrites the input it adds back
            buf = np.zeros(7, np.float32)
            buf[:5] = x
            mlp(buf[:5], out=buf)
            assert same_bits(buf, got)


def test_a_folding_mistake_is_caught(shipped):
    """The tolerance is tight enough to fail: a first-layer bias off by 1e-3 shows against the evaluation
    on the file's unfolded parameters."""
    mlp = make_mlp(shipped["stepper"].plain)
    x = np.random.default_rng(1).standard_normal(mlp.n_in).astype(np.float32)
    assert close(mlp(x), reference_mlp(mlp, x))
    m0 = mlp._single_plan()[2][0][0]
    m0[-1] += 1e-3                        # a bias off by 1e-3
    assert not close(mlp(x), reference_mlp(mlp, x))


def reference_xform_xy_to_quat(xy: np.ndarray) -> np.ndarray:
    """The pose decoding as written before the gathered version (per-column cross product and signs)."""
    signs = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]])
    a = xy[:, :, 0]
    a = a / np.sqrt(np.einsum("ij,ij->i", a, a))[:, None]
    b = xy[:, :, 1]
    b = b - np.einsum("ij,ij->i", a, b)[:, None] * a
    b = b / np.sqrt(np.einsum("ij,ij->i", b, b))[:, None]
    c = np.empty_like(a)
    c[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    c[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    c[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    diag = np.stack([a[:, 0], b[:, 1], c[:, 2]])
    q = 0.5 * np.sqrt(np.maximum(signs @ diag + 1.0, 0.0)).T
    q[:, 1] *= np.where(b[:, 2] - c[:, 1] < 0.0, -1.0, 1.0)
    q[:, 2] *= np.where(c[:, 0] - a[:, 2] < 0.0, -1.0, 1.0)
    q[:, 3] *= np.where(a[:, 1] - b[:, 0] < 0.0, -1.0, 1.0)
    return q / np.sqrt(np.einsum("ij,ij->i", q, q))[:, None]


#: how far the decoded rotations may be from the per-column Gram-Schmidt version (component-wise): the
#: decoding builds the same frame in another order (c = a x b, b = c x a, normalised together) and does not
#: normalise the quaternion again. Typically 1e-16; the bound is set by quaternions with a component near
#: zero (about 1e-8), whose square root (both versions take it from the matrix diagonal) turns a rounding
#: of the diagonal into about 1e-9 (2e-9 rad of rotation, nothing anyone sees)
DECODE_TOLERANCE = 1e-8


def test_pose_decoding_matches_the_per_column_version():
    """Rotations within DECODE_TOLERANCE of the per-column version, with the same signs (exact zeros and
    ties of signed axis permutations included: those come out bit for bit), of unit length to rounding;
    bone 0 exactly the identity; positions, velocities and contacts bit for bit."""
    from lmm.pose_decoding import PoseDecoder, xform_xy_to_quat
    decoder = PoseDecoder(23)
    rng = np.random.default_rng(11)
    worst, typical = 0.0, []
    for t in range(3000):
        y = rng.standard_normal(338) * rng.uniform(0.01, 3.0)    # a decompressor output, float64 as decoded
        if t % 3 == 0:   # signed axis permutations: exact (and negative) zeros and ties in the matrix
            for k in range(22):
                perm = np.eye(3)[rng.permutation(3)] * rng.choice([-1.0, 1.0], 3)
                y[66 + 6 * k: 72 + 6 * k] = perm[:, :2].reshape(-1)
        xy = y[66:198].reshape(22, 3, 2)
        got, ref = xform_xy_to_quat(xy), reference_xform_xy_to_quat(xy)
        if t % 3 == 0:
            assert np.array_equal(got, ref), f"pose {t}"
        worst = max(worst, float(np.abs(got - ref).max()))
        typical.append(float(np.median(np.abs(got - ref))))
        assert np.abs(np.sum(got * got, axis=1) - 1.0).max() <= 1e-15
        # the controller's decoder (one gather for all bones, bone 0 decoded from a constant identity)
        pose, want = decoder(y), reference_decode(y)
        assert np.array_equal(pose.rotations, np.concatenate([[[1.0, 0.0, 0.0, 0.0]], got]))
        for name in ("positions", "rotations", "velocities", "angular_velocities"):
            g, w = getattr(pose, name), want[name]
            assert g.shape == w.shape and g.flags.c_contiguous, f"pose {t}: {name}"
            if name != "rotations":
                assert np.array_equal(g.view(np.uint64), w.view(np.uint64)), f"pose {t}: {name}"
        assert np.array_equal(pose.contacts, want["contacts"]) and pose.frame == -1
    assert worst <= DECODE_TOLERANCE and np.median(typical) <= 1e-15


def reference_decode(y: np.ndarray) -> dict:
    """The pose decoding as written before the gathered decoder (23 bones, bone 0: root velocities)."""
    y = y.astype(np.float64)
    pos, rot, vel, ang = np.zeros((23, 3)), np.zeros((23, 4)), np.zeros((23, 3)), np.zeros((23, 3))
    pos[1:] = y[0:66].reshape(22, 3)
    rot[0, 0] = 1.0
    rot[1:] = reference_xform_xy_to_quat(y[66:198].reshape(22, 3, 2))
    vel[1:] = y[198:264].reshape(22, 3)
    ang[1:] = y[264:330].reshape(22, 3)
    vel[0], ang[0] = y[330:333], y[333:336]
    return {"positions": pos, "rotations": rot, "velocities": vel, "angular_velocities": ang,
            "contacts": y[336:338] > 0.5}


def test_decoded_poses_are_new_arrays_each_call():
    """Controllers keep source poses (the ghost reads one later): a decode never reuses earlier arrays."""
    from lmm.pose_decoding import PoseDecoder
    decoder = PoseDecoder(23)
    y = np.random.default_rng(2).standard_normal(338).astype(np.float32)
    first, second = decoder(y), decoder(-y)
    for name in ("positions", "rotations", "velocities", "angular_velocities", "contacts"):
        assert not np.may_share_memory(getattr(first, name), getattr(second, name)), name
    assert np.array_equal(first.positions[1:], y[:66].reshape(22, 3))


def test_learned_controller_with_the_folded_networks_stays_within_a_millimetre(db, features, monkeypatch):
    """The recordings' tolerance (issue 16): 30 s of builtin:random:1 through the learned controller with
    the folded batch-1 networks against the same run with the plain evaluation (what the recordings were
    made with before): every joint of every tick within 1 mm, and the same projector decisions."""
    from lmm.learned import LearnedMotionMatchingController, load_default_networks

    def run(plain: bool):
        nets = load_default_networks(db, features)
        if plain:
            arrays = dict(np.load(DEFAULT_WEIGHTS))
            for name in ("decompressor", "stepper", "projector"):
                mlp = getattr(nets, name)
                mlp.plain = plain_params(arrays, name, skip=name == "projector")
                monkeypatch.setattr(mlp, "_call_single", lambda x, out, m=mlp: _plain_into(m, x, out))
                # the controller binds its per-tick calls: route them through the plain evaluation too
                monkeypatch.setattr(mlp, "bind_single", lambda out, x1=None, m=mlp:
                                    lambda x=None: m._call_single(x1[:-1] if x is None else x, out))
        c = LearnedMotionMatchingController(db, features, networks=nets, compare_with_search=False)
        return _run_30s(c, "matched_frame")

    folded, f_frames = run(False)
    plain, p_frames = run(True)
    err = np.abs(folded - plain).max()
    assert err <= 1e-3, f"the folded networks move a joint by {err * 1000:.2f} mm"
    assert f_frames == p_frames
    assert err > 0  # the plain evaluation really ran (different bits): the comparison can fail


def _run_30s(controller, field: str):
    """30 s of builtin:random:1 through ``controller``: every tick's global positions (float64) and the
    snapshots' ``field``."""
    from lmm.data.inputs import builtin

    log, dt = builtin("random:1", 30.0), 1.0 / 60.0
    poses, values = [], []
    for i in range(1800):
        pose, snap = controller.step(log.at(i * dt), dt)
        poses.append(pose.global_positions.astype(np.float64))
        values.append(getattr(snap, field))
    return np.array(poses), values


def _plain_into(mlp, x, out):
    y = reference_mlp(mlp, np.asarray(x))
    if out is None:
        return y
    out[...] = y
    return out


def _call_single_as_on_main(mlp: MLP, x: np.ndarray, out) -> np.ndarray:
    """``MLP._call_single`` as it was before :meth:`MLP.bind_single` (main 81f3b27), relu, no skip."""
    x1, x_view, hidden, last, y_last = mlp._single_plan()
    x_view[...] = x
    h = x1
    for m, buf, val, zero, _ in hidden:
        np.dot(h, m, out=val)
        np.maximum(val, zero, out=val)
        h = buf
    y = np.empty_like(y_last)
    np.dot(h, last, out=y)
    out[...] = y
    return out


@pytest.mark.parametrize("name", ["decompressor", "stepper", "projector"])
def test_bound_single_calls_are_bit_identical(shipped, name):
    """bind_single (with its own input copy, or reading the caller's [x, 1] buffer) gives the bits of
    _call_single and of main's version of it."""
    mlp = shipped[name]
    rng = np.random.default_rng(5)
    out = np.empty(mlp.n_out, np.float32)
    x1 = np.ones(mlp.n_in + 1, np.float32)
    run_copy, run_x1 = mlp.bind_single(out), mlp.bind_single(out, x1)
    for t in range(100):
        x = (rng.standard_normal(mlp.n_in) * rng.uniform(0.1, 3.0)).astype(np.float32)
        want = mlp._call_single(x, None).copy()
        assert same_bits(run_copy(x), want)
        x1[:-1] = x
        assert same_bits(run_x1(), want) and same_bits(out, want)
        if not mlp.skip:
            assert same_bits(_call_single_as_on_main(mlp, x, np.empty_like(out)), want)


@pytest.mark.parametrize("name", ["decompressor", "stepper", "projector"])
def test_call_with_out_uses_bound_call_with_the_same_bits(shipped, name):
    """``mlp(x, out)`` on one float32 vector goes through a bound call kept for ``out``: the bits of
    _call_single, whichever of two buffers is given (the binding follows ``out``), with ``x`` a view of
    ``out`` itself, and with a float64 ``x`` or a float64 ``out`` (both left to _call_single)."""
    mlp = shipped[name]
    rng = np.random.default_rng(11)
    outs = [np.empty(mlp.n_out, np.float32), np.empty(mlp.n_out, np.float32)]
    for t in range(40):
        x = (rng.standard_normal(mlp.n_in) * rng.uniform(0.1, 3.0)).astype(np.float32)
        want = mlp._call_single(x, None).copy()
        out = outs[t % 2]
        assert mlp(x, out) is out and same_bits(out, want)
        assert mlp._bound[0] is out
        shared = np.zeros(max(mlp.n_in, mlp.n_out), np.float32)[:mlp.n_out]
        shared[:mlp.n_in] = x
        assert same_bits(mlp(shared[:mlp.n_in], shared), want)
        x64 = x.astype(np.float64)
        assert same_bits(mlp(x64, outs[0]), mlp._call_single(x64, None))
        out64 = np.empty(mlp.n_out)
        assert np.array_equal(mlp(x, out64), want.astype(np.float64))


def test_bind_single_rejects_bad_buffers(shipped):
    mlp = shipped["stepper"]
    with pytest.raises(ValueError, match="float32"):
        mlp.bind_single(np.empty(mlp.n_out))
    with pytest.raises(ValueError, match="ending with 1.0"):
        mlp.bind_single(np.empty(mlp.n_out, np.float32), np.zeros(mlp.n_in + 1, np.float32))
    proj = shipped["projector"]
    buf = np.ones(proj.n_in + proj.n_out + 1, np.float32)
    with pytest.raises(ValueError, match="skip"):
        proj.bind_single(buf[1:proj.n_out + 1], buf[:proj.n_in + 1])   # out overlaps the input


def test_learned_controller_ticks_bit_identical_to_mains_hooks(db, features):
    """The controller's bound network calls, its state buffer and its cached source features give the
    bits of main's hooks (written out below): 20 s of builtin:random:1, every pose and snapshot field
    the learned controller fills."""
    from lmm.data.inputs import builtin
    from lmm.learned import LearnedMotionMatchingController, load_default_networks

    class AsOnMain(LearnedMotionMatchingController):
        def decompress(self, state):
            self.nets.decompressor(state, out=self._pose_vec)
            return self._decode(self._pose_vec)

        def _source_features(self):
            return self.nets.from_network_space(self.state[:self.nets.n_features])

        def _advance_pose(self, dt):
            if dt > 0:
                deriv = self._deriv
                self.nets.stepper(self.state, out=deriv)
                np.multiply(deriv, np.float32(dt), out=deriv)
                self.state += deriv
            # the per-tick decompression and decoding, as the controller does them (compared with the
            # whole decompressor in test_learned_controller_with_the_tick_decoding_stays_within_ten_micrometres)
            self._run_decompressor_tick()
            hidden = self._decompressor_hidden.copy()
            return self._decode.tick(self._pose_tick, lambda: np.dot(hidden, self._decompressor_velocities))

    nets = load_default_networks(db, features)
    fast = LearnedMotionMatchingController(db, features, networks=nets, compare_with_search=False)
    main = AsOnMain(db, features, networks=load_default_networks(db, features), compare_with_search=False)
    log, dt = builtin("random:1", 20.0), 1.0 / 60.0
    jumps = 0
    for i in range(1200):
        inp = log.at(i * dt)
        (p1, s1), (p2, s2) = fast.step(inp, dt), main.step(inp, dt)
        for name in ("global_positions", "global_rotations", "local_positions", "local_rotations", "contacts"):
            assert np.array_equal(getattr(p1, name), getattr(p2, name)), f"tick {i}: {name}"
        for name in ("latent", "projected_features", "current_features", "query"):
            a, b = getattr(s1, name), getattr(s2, name)
            assert a.dtype == b.dtype and np.array_equal(a.view(np.uint32), b.view(np.uint32)), f"tick {i}: {name}"
        assert s1.transitioned == s2.transitioned and s1.matched_frame == s2.matched_frame
        jumps += s1.transitioned
    assert jumps > 5  # projections jumped the state: the cached features were invalidated and recomputed


def test_learned_controller_with_the_tick_decoding_stays_within_ten_micrometres(db, features):
    """The recordings' tolerance for the per-tick decoding: 30 s of builtin:random:1 with the controller's
    tick path (the decompressor's tick columns, the fast decoding, the velocities when read) against the
    same run evaluating the whole decompressor and decoding with the per-column Gram-Schmidt version
    (what the recordings were made with before): every joint of every tick within 10 um, the same
    projector decisions."""
    from lmm.source_pose import SourcePose
    from lmm.learned import LearnedMotionMatchingController, load_default_networks

    def per_column(y):
        want = reference_decode(np.asarray(y, np.float64))
        return SourcePose(want["positions"], want["rotations"], want["velocities"], want["angular_velocities"],
                          want["contacts"], -1)

    def run(reference: bool):
        c = LearnedMotionMatchingController(db, features, networks=load_default_networks(db, features),
                                            compare_with_search=False)
        if reference:
            c._decode = per_column

            def advance(dt, c=c):
                if dt > 0:
                    c._run_stepper()
                    np.multiply(c._deriv, np.float32(dt), c._deriv)
                    np.add(c.state, c._deriv, c.state)
                    c._source_raw = None
                c._run_decompressor()
                return per_column(c._pose_vec)
            c._advance_pose = advance
        return _run_30s(c, "transitioned")

    fast, f_jumps = run(False)
    ref, r_jumps = run(True)
    err = np.abs(fast - ref).max()
    print(f"tick decoding against the whole vector, per column: {err:.3g} m")
    assert err <= 1e-5, f"the decoding moves a joint by {err * 1e6:.3f} um"
    assert f_jumps == r_jumps and sum(f_jumps) > 5
    assert err > 0  # the reference decoding really ran: the comparison can fail


def test_split_decompressor_gives_the_whole_outputs_within_float32_rounding(shipped):
    """bind_single_split: the tick columns from run(), the others from the hidden layer's copy and the
    rest matrix, both within float32 rounding of the whole network's outputs; bad arguments refused."""
    from lmm.nn import pose_vector_tick_columns, pose_vector_velocity_columns

    mlp = shipped["decompressor"]
    tick, vel = pose_vector_tick_columns(23), pose_vector_velocity_columns(23)
    assert len(tick) + len(vel) == mlp.n_out and not set(tick) & set(vel)
    x1 = np.ones(mlp.n_in + 1, np.float32)
    out = np.empty(len(tick), np.float32)
    run, hidden, rest = mlp.bind_single_split(tick, out, x1)
    rng = np.random.default_rng(9)
    for t in range(200):
        x1[:-1] = rng.standard_normal(mlp.n_in) * rng.uniform(0.1, 3.0)
        whole = mlp._call_single(x1[:-1].copy(), None).copy()
        run()
        scale = np.abs(whole).max()
        assert np.abs(out - whole[tick]).max() <= 1e-6 * scale
        assert np.abs(np.dot(hidden.copy(), rest) - whole[vel]).max() <= 1e-6 * scale
    with pytest.raises(ValueError, match="ascending"):
        mlp.bind_single_split(tick[::-1], out, x1)
    with pytest.raises(ValueError, match="float32"):
        mlp.bind_single_split(tick, np.empty(len(tick)), x1)
    with pytest.raises(ValueError, match="ending with 1.0"):
        mlp.bind_single_split(tick, out, np.zeros(mlp.n_in + 1, np.float32))
    with pytest.raises(ValueError, match="skip"):
        shipped["projector"].bind_single_split([0, 1], np.empty(2, np.float32), np.ones(shipped["projector"].n_in + 1, np.float32))


def test_tick_decoding_is_the_whole_vectors_decoding_bit_for_bit():
    """PoseDecoder.tick on the tick columns, with the velocity columns given when read, decodes exactly
    what __call__ decodes from the whole vector; the velocities are made only when read, once."""
    from lmm.pose_decoding import PoseDecoder
    from lmm.nn import pose_vector_tick_columns, pose_vector_velocity_columns

    decoder = PoseDecoder(23)
    tick, vel = pose_vector_tick_columns(23), pose_vector_velocity_columns(23)
    rng = np.random.default_rng(4)
    for t in range(50):
        y = (rng.standard_normal(338) * rng.uniform(0.1, 3.0)).astype(np.float32)
        calls = []

        def velocities():
            calls.append(1)
            return y[vel]

        got, want = decoder.tick(y[tick], velocities), decoder(y)
        assert calls == []
        assert got.root_velocity_floats() == (want.velocities[0].tolist(), want.angular_velocities[0].tolist())
        for name in ("positions", "rotations", "velocities", "angular_velocities", "contacts"):
            a, b = getattr(got, name), getattr(want, name)
            assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), name
        assert calls == [1] and got.frame == -1


@pytest.mark.parametrize("name", ["decompressor", "stepper", "projector"])
def test_every_layer_is_kept_once(name):
    """Issue 38 (memory): each layer is one matrix (bias as its last row) with the normalisation folded in;
    the weights and biases are views of it, the hidden-to-hidden layers the file's very values, and
    ``nbytes`` counts them once; building the batch-1 plan copies no layer and changes no batched bit."""
    arrays = dict(np.load(DEFAULT_WEIGHTS))
    mlp = MLP.from_arrays(arrays, name, "relu", skip=name == "projector")
    x = np.random.default_rng(3).standard_normal((64, mlp.n_in)).astype(np.float32)
    before, size = mlp(x), mlp.nbytes()
    mlp(x[0])                                        # builds the plan
    mats = [m for m, *_ in mlp._plan[2]] + [mlp._plan[3]]
    assert len(mats) == len(mlp.weights)
    for i, m in enumerate(mats):
        assert mlp.weights[i].base is m and mlp.biases[i].base is m
        if 0 < i < len(mats) - 1:
            assert np.array_equal(mlp.weights[i], arrays[f"{name}.W{i}"])
            assert np.array_equal(mlp.biases[i], arrays[f"{name}.b{i}"])
    params = sum(arrays[f"{name}.W{i}"].nbytes + arrays[f"{name}.b{i}"].nbytes for i in range(len(mats)))
    identity = 4 * (mlp.n_in + mlp.n_out) * 2
    assert mlp.nbytes() == size == params + identity
    assert same_bits(mlp(x), before)
    last = len(mats) - 1                                              # the normalisation is folded in
    assert not (np.array_equal(mlp.weights[0], arrays[f"{name}.W0"])
                and np.array_equal(mlp.weights[last], arrays[f"{name}.W{last}"]))
