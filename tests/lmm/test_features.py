"""Feature channels against an independent slow computation, normalisation and weights."""
from __future__ import annotations

import numpy as np
import pytest

from lmm import quat
from lmm.data.build import load_or_build
from lmm.features import DEFAULT_LAYOUT, Channel, build_features, build_query


@pytest.fixture(scope="module")
def db(tmp_path_factory):
    return load_or_build(cache_dir=tmp_path_factory.mktemp("dbcache"))[0]


@pytest.fixture(scope="module")
def feats(db):
    return build_features(db)


def slow_global_matrices(db, frame):
    """Per-frame forward kinematics with 4x4 homogeneous matrices and a Python loop over bones."""
    mats = []
    for j, p in enumerate(db.parents):
        local = np.eye(4)
        local[:3, :3] = quat.to_matrix(db.rotations[frame, j].astype(np.float64))
        local[:3, 3] = db.positions[frame, j]
        mats.append(local if p < 0 else mats[p] @ local)
    return np.stack(mats)


def slow_features(db, frame):
    """The 27-D feature of one frame from first principles (velocities: finite differences of FK positions)."""
    m = slow_global_matrices(db, frame)
    root_inv = np.linalg.inv(m[0])
    to_root = lambda p: (root_inv @ np.append(p, 1.0))[:3]
    to_root_dir = lambda v: root_inv[:3, :3] @ v

    s = db.range_starts[db.range_index(frame)]
    e = db.range_stops[db.range_index(frame)]
    lo, hi = max(frame - 1, s), min(frame + 1, e - 1)
    m_lo, m_hi = slow_global_matrices(db, lo), slow_global_matrices(db, hi)
    vel = lambda b: (m_hi[b, :3, 3] - m_lo[b, :3, 3]) / ((hi - lo) / db.fps)

    lf, rf, hips = db.bone("left_foot"), db.bone("right_foot"), db.bone("hips")
    out = [to_root(m[lf, :3, 3]), to_root(m[rf, :3, 3]), to_root_dir(vel(lf)), to_root_dir(vel(rf)),
           to_root_dir(vel(hips))]
    traj_p, traj_d = [], []
    for off in (20, 40, 60):
        f = min(frame + off, e - 1)
        mf = slow_global_matrices(db, f)
        traj_p.append(to_root(mf[0, :3, 3])[[0, 2]])
        traj_d.append(to_root_dir(mf[0, :3, :3] @ np.array([0.0, 0.0, 1.0]))[[0, 2]])
    return np.concatenate(out + traj_p + traj_d)


def test_layout_is_the_papers_27d(feats):
    assert feats.n_dims == 27
    assert [s.start for s in feats.slices] == [0, 3, 6, 9, 12, 15, 21]
    assert feats.weights.tolist() == [0.75, 0.75, 1.0, 1.0, 1.0, 1.0, 1.5]


def test_channels_match_slow_computation(db, feats):
    rng = np.random.default_rng(7)
    frames = rng.choice(db.n_frames, 40, replace=False)
    # include range starts and ends, where futures clamp and differences are one-sided
    frames = np.concatenate([frames, db.range_starts[:3], db.range_stops[:3] - 1])
    for f in frames:
        ref = slow_features(db, int(f))
        got = feats.raw[f]
        for ch, s in zip(feats.layout, feats.slices):
            assert np.abs(got[s] - ref[s]).max() < 1e-3, (ch.name, f, got[s], ref[s])


def test_normalised_features_have_zero_mean(feats):
    assert np.abs(feats.normalized.mean(axis=0)).max() < 1e-3
    # and each group has unit mean std divided by... the weight
    for i, s in enumerate(feats.slices):
        assert feats.normalized[:, s].std(axis=0).mean() == pytest.approx(feats.weights[i], rel=1e-3)


def test_changing_a_weight_rescales_without_recomputing(feats):
    raw_before = feats.raw
    raw_copy = feats.raw.copy()
    before = feats.normalized.copy()
    i = feats.channel_index("trajectory_direction")
    s = feats.slices[i]
    assert feats.set_weights({"trajectory_direction": 3.0})
    assert feats.raw is raw_before and np.array_equal(feats.raw, raw_copy)
    assert np.allclose(feats.normalized[:, s], before[:, s] * 2.0, atol=1e-5)
    other = feats.slices[0]
    assert np.array_equal(feats.normalized[:, other], before[:, other])
    assert not feats.set_weights({"trajectory_direction": 3.0})  # unchanged -> no work
    feats.set_weights({"trajectory_direction": 0.0})
    assert np.all(feats.normalized[:, s] == 0)
    feats.set_weights({"trajectory_direction": 1.5})
    assert np.allclose(feats.normalized, before, atol=1e-5)
    with pytest.raises(KeyError, match="no feature channel"):
        feats.set_weights({"nose_velocity": 1.0})
    with pytest.raises(ValueError):
        feats.set_weights({"hip_velocity": -1.0})


def test_custom_layout_adds_and_removes_channels(db):
    layout = [ch for ch in DEFAULT_LAYOUT if ch.name != "hip_velocity"]
    layout.append(Channel("head_position", "bone_position", "Head", weight=0.5))
    layout.append(Channel("far_trajectory", "trajectory_position", offsets=(90,), weight=1.0))
    f = build_features(db, layout)
    assert f.n_dims == 27 - 3 + 3 + 2
    head = f.raw[:, f.slices[f.channel_index("head_position")]]
    assert 1.3 < np.median(head[:, 1]) < 1.9  # head height in metres
    with pytest.raises(ValueError, match="needs a bone"):
        Channel("bad", "bone_velocity")
    with pytest.raises(KeyError):
        build_features(db, [Channel("x", "bone_position", "NoSuchBone")])


def test_normalize_denormalize_round_trip(feats):
    x = feats.raw[:100]
    assert np.allclose(feats.denormalize(feats.normalize(x)), x, atol=1e-4)


def test_build_query_takes_trajectory_from_the_callback(feats):
    current = feats.raw[1234]
    q = build_query(feats, current, lambda off: (np.array([off, 0.0, 2 * off]), np.array([0.0, 0.0, 1.0])))
    s = feats.slices[feats.channel_index("trajectory_position")]
    assert q[s].tolist() == [20, 40, 40, 80, 60, 120]
    assert np.array_equal(q[:15], current[:15])
