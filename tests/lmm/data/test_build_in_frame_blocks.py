"""Bulk per-frame maths (the database build's forward kinematics, its inverse, angular velocities, sign
unrolling, cubic resampling) runs a block of frames at a time on long takes: the same bits as in one go,
and the same database."""
from __future__ import annotations

import json

import numpy as np
import pytest

import lmm.filters as filters
from lmm import DATA_DIR, kinematics, quat
from lmm.data.build import build
from lmm.data.manifest import load_manifest
from lmm.data.preparation import quat_central_difference, resampled_length

PARENTS = [-1, 0, 1, 2, 3, 0, 5, 6, 7, 0, 9, 10, 11, 12, 11, 14, 15, 11, 17, 18]


def _motion(frames: int, dtype=np.float64, seed: int = 0):
    rng = np.random.default_rng(seed)
    rot = quat.normalize(rng.standard_normal((frames, len(PARENTS), 4))).astype(dtype)
    pos = rng.standard_normal((frames, len(PARENTS), 3)).astype(dtype)
    return rot, pos


def _same(a, b) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("dtypes", [(np.float64, np.float64), (np.float32, np.float32), (np.float32, np.float64)])
def test_forward_kinematics_in_blocks_is_the_per_joint_formula(monkeypatch, dtypes):
    monkeypatch.setattr(quat, "FRAME_BLOCK", 64)
    rot, _ = _motion(333, dtypes[0])
    _, pos = _motion(333, dtypes[1], seed=1)
    g_rot, g_pos = kinematics.forward_kinematics(rot, pos, PARENTS)
    # the definition, joint by joint over every frame at once
    want_rot = np.empty(g_rot.shape, g_rot.dtype)
    want_pos = np.empty(g_pos.shape, g_pos.dtype)
    for j, p in enumerate(PARENTS):
        if p < 0:
            want_rot[:, j], want_pos[:, j] = rot[:, j], pos[:, j]
        else:
            want_rot[:, j] = quat.mul(want_rot[:, p], rot[:, j])
            want_pos[:, j] = quat.mul_vec(want_rot[:, p], pos[:, j]) + want_pos[:, p]
    assert g_rot.dtype == np.result_type(*dtypes)
    assert _same(g_rot, want_rot) and _same(g_pos, want_pos)


def test_global_to_local_in_blocks_is_the_per_joint_formula(monkeypatch):
    rot, pos = _motion(300)
    monkeypatch.setattr(quat, "FRAME_BLOCK", 10**9)   # one go: the per-joint formula over every frame
    whole = kinematics.global_to_local(rot, pos, PARENTS)
    monkeypatch.setattr(quat, "FRAME_BLOCK", 50)
    blocks = kinematics.global_to_local(rot, pos, PARENTS)
    assert all(_same(a, b) for a, b in zip(whole, blocks))
    # and it inverts forward kinematics (to rounding)
    local_rot, local_pos = kinematics.global_to_local(*kinematics.forward_kinematics(rot, pos, PARENTS), PARENTS)
    assert np.allclose(np.abs(np.sum(local_rot * rot, axis=-1)), 1.0) and np.allclose(local_pos[:, 1:], pos[:, 1:])


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_angular_velocities_in_blocks(monkeypatch, dtype):
    rot, _ = _motion(300, dtype)
    rot[150:] *= -1.0   # a sign flip on the way: abs_ takes the short way round
    monkeypatch.setattr(quat, "FRAME_BLOCK", 10**9)
    whole = quat_central_difference(rot, 1 / 60)
    monkeypatch.setattr(quat, "FRAME_BLOCK", 64)
    assert _same(whole, quat_central_difference(rot, 1 / 60))
    inner = quat.to_scaled_angle_axis(quat.abs_(quat.mul_inv(rot[2:], rot[:-2]))) / (2 / 60)
    assert _same(whole[1:-1], inner.astype(np.float64))


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("shape, axis", [((700, 5, 4), 0), ((5, 700, 4), 1), ((1, 4), 0), ((2, 4), 0)])
def test_unroll_in_blocks_is_the_definition(monkeypatch, dtype, shape, axis):
    monkeypatch.setattr(quat, "FRAME_BLOCK", 64)
    q = np.random.default_rng(2).standard_normal(shape).astype(dtype)
    # the definition: flip the sign of every frame after an odd number of hemisphere changes
    t = np.moveaxis(q.copy(), axis, 0)
    if len(t) > 1:
        flips = np.cumsum(np.sum(t[1:] * t[:-1], axis=-1) < 0.0, axis=0) % 2
        t = t * np.concatenate([np.ones_like(flips[:1]), 1 - 2 * flips], axis=0)[..., None]
    want = np.moveaxis(t, 0, axis)
    got = quat.unroll(q, axis)
    assert _same(got, want)
    assert len(np.moveaxis(got, axis, 0)) < 2 or (np.sum(np.moveaxis(got, axis, 0)[1:] * np.moveaxis(got, axis, 0)[:-1], -1) >= 0).all()


def test_catmull_rom_in_blocks(monkeypatch):
    x = np.random.default_rng(3).standard_normal((400, 7, 4))
    t = np.arange(0.0, 399 + 1e-9, 30 / 60 * 1.1)
    monkeypatch.setattr(filters, "CATMULL_ROM_BLOCK", 10**9)
    whole = filters.catmull_rom(x, t)
    monkeypatch.setattr(filters, "CATMULL_ROM_BLOCK", 37)
    assert _same(whole, filters.catmull_rom(x, t))
    assert whole.shape == (len(t), 7, 4) and np.allclose(filters.catmull_rom(x, np.arange(400.0)), x)


def test_a_database_built_in_small_blocks_is_the_same(tmp_path, monkeypatch):
    """Every blocked step of the build at once, with blocks far smaller than the takes."""
    path = tmp_path / "m.json"
    path.write_text(json.dumps({"name": "blocks", "clips": [
        {"file": str(DATA_DIR / "lafan1" / "obstacles3_subject4.bvh.gz"), "ranges": [[100, 700]]}]}))
    m = load_manifest(path)
    monkeypatch.setattr(quat, "FRAME_BLOCK", 10**9)
    monkeypatch.setattr(filters, "CATMULL_ROM_BLOCK", 10**9)
    whole, whole_meta = build(m).to_archive()
    monkeypatch.setattr(quat, "FRAME_BLOCK", 97)
    monkeypatch.setattr(filters, "CATMULL_ROM_BLOCK", 101)
    blocks, blocks_meta = build(m).to_archive()
    assert whole_meta == blocks_meta and set(whole) == set(blocks)
    for name in whole:
        assert _same(np.asarray(whole[name]), np.asarray(blocks[name])), name


def test_workers_leave_no_spill_files(tmp_path, monkeypatch):
    """Worker processes hand their takes back through files in a temporary folder, removed after the
    build."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    path = tmp_path / "m.json"
    path.write_text(json.dumps({"name": "spill", "clips": [
        {"file": str(DATA_DIR / "lafan1" / "obstacles3_subject4.bvh.gz"), "ranges": [[0, 200]]},
        {"file": str(DATA_DIR / "lafan1" / "obstacles3_subject3.bvh.gz"), "ranges": [[0, 150]]}]}))
    db = build(load_manifest(path), workers=2)
    assert db.n_frames == 2 * (resampled_length(200, 30, 60) + resampled_length(150, 30, 60))
    assert not list(tmp_path.glob("lmm-build-*"))
    assert isinstance(db.positions, np.ndarray) and not isinstance(db.positions, np.memmap)
