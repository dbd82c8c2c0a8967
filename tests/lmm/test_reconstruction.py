"""The reconstruction benchmark (lmm.reconstruction, ``lmm-studio eval --reconstruction``)."""
import json

import numpy as np
import pytest

from lmm import DEFAULT_MANIFEST
from lmm.data.manifest import load_manifest
from lmm.reconstruction import HELDOUT_FILE, HeldOut, format_table, load_heldout, run_take, summarize


def test_heldout_ranges_are_not_used_by_the_default_database():
    m = load_manifest(DEFAULT_MANIFEST)
    used = {c.file.name: c.ranges for c in m.clips}
    takes, _ = load_heldout(HELDOUT_FILE, shared_dir="/nonexistent")   # the shipped ones at least
    assert len(takes) >= 3 and {t.motion for t in takes} >= {"walk", "run"}
    for t in takes:
        a, b = t.frames
        for ua, ub in used.get(t.file.name, []):
            assert b <= ua or ub <= a, (t.name, t.frames, (ua, ub))


def _root_relative_cm(g_rot, g_pos_m, forward):
    """Root-relative joint positions (cm) written out here, independently of lmm.compare: each pose minus
    the hips' ground position, turned by minus the yaw of the hips' forward axis."""
    w, u = g_rot[:, 0, :1], g_rot[:, 0, 1:]
    v = np.broadcast_to(np.asarray(forward, float), u.shape)
    t = 2.0 * np.cross(u, v)
    f = v + w * t + np.cross(u, t)                       # the forward axis rotated by the hips
    yaw = np.arctan2(f[:, 0], f[:, 2])[:, None]
    rel = (g_pos_m - g_pos_m[:, :1] * np.array([1.0, 0.0, 1.0])) * 100.0
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([c * rel[..., 0] - s * rel[..., 2], rel[..., 1], s * rel[..., 0] + c * rel[..., 2]], axis=-1)


@pytest.fixture(scope="module")
def db_and_oracle():
    from lmm.data.build import load_or_build
    from lmm.reconstruction import PoseOracle
    db, _ = load_or_build(None)
    return db, PoseOracle(db, load_manifest(DEFAULT_MANIFEST).hips_forward_axis)


def test_the_pose_oracle_finds_the_database_pose_of_least_root_relative_error(db_and_oracle):
    db, oracle = db_and_oracle
    forward = load_manifest(DEFAULT_MANIFEST).hips_forward_axis
    frames = np.arange(0, db.n_frames, 997)
    g_rot, g_pos = db.global_transforms(frames)
    want = _root_relative_cm(g_rot[:, 1:], g_pos[:, 1:], forward)      # bone 0 is the simulation bone
    assert np.allclose(oracle.local_cm[frames], want, atol=1e-3)
    rng = np.random.default_rng(3)
    table = oracle.local_cm.astype(np.float64)
    for pose in want[:4] + rng.normal(0.0, 4.0, want[:4].shape):
        errors = np.linalg.norm(table - pose, axis=2).mean(axis=1)
        frame, err = oracle.nearest(pose)
        assert frame == int(np.argmin(errors)) and err == pytest.approx(errors.min(), rel=1e-12)


def test_a_held_out_range_through_mm(tmp_path, db_and_oracle):
    from lmm.data import bvh
    from lmm.factory import make_controller
    from lmm.features import build_features
    db, oracle = db_and_oracle
    features = build_features(db)
    m = load_manifest(DEFAULT_MANIFEST)
    takes, _ = load_heldout(HELDOUT_FILE, shared_dir="/nonexistent")
    walk = next(t for t in takes if t.motion == "walk")
    short = HeldOut(walk.file, walk.name, (walk.frames[0], walk.frames[0] + 120), walk.motion)
    r = run_take(short, db, features, m, {"mm": make_controller("mm", db, features)}, oracle=oracle)
    # the baselines: the take's mean root-relative pose held, against the same poses computed here
    anim = bvh.load(short.file)
    g_rot, g_pos = anim.global_transforms()
    a, b = short.frames
    take = _root_relative_cm(g_rot[a:b], g_pos[a:b] * m.unit_scale, m.hips_forward_axis)
    mean_pose = np.linalg.norm(take - take.mean(axis=0), axis=2).mean()
    base = r["baselines"]
    assert base["mean_pose_root_relative_cm"] == pytest.approx(mean_pose, rel=1e-9)
    assert len(base["per_tick_nearest_frame_cm"]) == 120 and base["nearest_frame_stride"] == 1
    assert 0.0 < base["nearest_frame_root_relative_cm"] <= base["mean_pose_root_relative_cm"]
    frame, err = base["nearest_frames"][7], base["per_tick_nearest_frame_cm"][7]
    assert err == pytest.approx(np.linalg.norm(oracle.local_cm[frame] - take[7], axis=1).mean(), rel=1e-5)
    c = r["controllers"]["mm"]
    assert abs(r["seconds"] - 4.0) < 0.05 and r["input_path_error"]["position_mean_m"] < 0.2
    # a controller's walk is not the take's walk, but it is a walk in the same place
    assert 0.02 < c["rotation_error_rad"] < 1.0 and c["root_path_error_cm"] < 30.0
    assert 0.0 < c["position_error_cm"]["root_relative"] < 40.0
    assert len(c["per_frame_rotation_error_rad"]) == 120 and np.isfinite(c["per_frame_rotation_error_rad"]).all()
    s = summarize([r], ["mm"])
    assert s["walk"]["mm"]["rotation_error_rad"] == pytest.approx(c["rotation_error_rad"])
    assert s["all"]["baselines"]["mean_pose_root_relative_cm"] == pytest.approx(mean_pose, rel=1e-9)
    table = format_table([r], s, ["mm"])
    assert "| **all** (1 takes)" in table and "nearest pose (every frame of each take)" in table
    assert f"| {mean_pose:.1f} / {base['nearest_frame_root_relative_cm']:.1f} |" in table


def test_a_broken_heldout_list_is_one_line(tmp_path):
    from lmm.errors import InputError
    bad = tmp_path / "h.json"
    bad.write_text(json.dumps({"takes": [{"file": "x.bvh"}]}))
    with pytest.raises(InputError, match=r"h\.json: takes\[0\]"):
        load_heldout(bad)
