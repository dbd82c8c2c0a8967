"""lmm.kinematics against per-frame, per-joint 4x4 homogeneous transforms."""
from __future__ import annotations

import numpy as np
import pytest

from lmm import kinematics, quat
from lmm.kinematics import PoseSkeleton, pose_forward_kinematics, pose_forward_kinematics_update
from lmm.skeleton import subtree as subtree_joints


def _slow_fk(local_rot, local_pos, parents):
    """Per frame, per joint 4x4 homogeneous transforms: G[j] = G[parent] @ T(local)."""
    F, J = local_pos.shape[:2]
    g_mat = np.zeros((F, J, 3, 3))
    g_pos = np.zeros((F, J, 3))
    for f in range(F):
        world = [None] * J
        for j in range(J):
            t = np.eye(4)
            t[:3, :3] = quat.to_matrix(local_rot[f, j])
            t[:3, 3] = local_pos[f, j]
            world[j] = t if parents[j] < 0 else world[parents[j]] @ t
            g_mat[f, j] = world[j][:3, :3]
            g_pos[f, j] = world[j][:3, 3]
    return g_mat, g_pos


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


@pytest.mark.parametrize("parents", [
    [-1, 0, 1, 2, 3],
    [-1, 0, 0, 1, 2, 2, 0],
    [-1, 0, -1, 2, 2, 0],  # two roots
])
def test_forward_kinematics_matches_slow_loop(parents, rng):
    F, J = 12, len(parents)
    local_rot = quat.normalize(rng.normal(size=(F, J, 4)))
    local_pos = rng.normal(scale=10.0, size=(F, J, 3))
    g_rot, g_pos = kinematics.forward_kinematics(local_rot, local_pos, np.array(parents))
    s_mat, s_pos = _slow_fk(local_rot, local_pos, parents)
    np.testing.assert_allclose(g_pos, s_pos, atol=1e-9)
    np.testing.assert_allclose(quat.to_matrix(g_rot), s_mat, atol=1e-12)


def test_global_local_round_trip():
    rng = np.random.default_rng(3)
    parents = np.array([-1, 0, 1, 1, 3])
    rot = quat.normalize(rng.normal(size=(7, 5, 4)))
    pos = rng.normal(size=(7, 5, 3))
    g_rot, g_pos = kinematics.forward_kinematics(rot, pos, parents)
    l_rot, l_pos = kinematics.global_to_local(g_rot, g_pos, parents)
    assert np.allclose(l_pos, pos, atol=1e-9)
    assert np.allclose(np.abs(np.sum(l_rot * rot, -1)), 1.0, atol=1e-9)


# -- one pose in plain floats -----------------------------------------------------------------------

def _random_pose(rng, n):
    rot = quat.normalize(rng.normal(size=(n, 4)))
    pos = rng.normal(size=(n, 3))
    return rot, pos


def test_subtree_joints_are_descendants_in_order(db):
    parents = [int(p) for p in db.parents]
    foot = db.bone("left_foot")
    knee = parents[foot]
    hip = parents[knee]
    joints = subtree_joints(parents, [hip])
    assert joints == sorted(joints) and hip in joints and foot in joints and db.bone("left_toe") in joints
    assert db.bone("right_foot") not in joints and 0 not in joints
    for j in joints:
        assert j == hip or parents[j] in joints


def forward_kinematics_pose(rot, pos, parents):
    """:func:`pose_forward_kinematics` as two arrays."""
    g, p = pose_forward_kinematics(rot, pos, parents)
    return np.array(g), np.array(p)


def forward_kinematics_update(g_rot, g_pos, rot, pos, parents, joints):
    """:func:`pose_forward_kinematics_update` on copies of array inputs, as two new arrays."""
    g, p = g_rot.tolist(), g_pos.tolist()
    pose_forward_kinematics_update(g, p, rot.tolist(), pos.tolist(), parents, joints)
    return np.array(g), np.array(p)


def test_partial_forward_kinematics_is_bit_identical(db):
    parents = [int(p) for p in db.parents]
    rng = np.random.default_rng(3)
    legs = [parents[parents[db.bone(f)]] for f in ("left_foot", "right_foot")]
    for _ in range(50):
        rot, pos = _random_pose(rng, db.n_bones)
        g_rot, g_pos = forward_kinematics_pose(rot, pos, parents)
        changed = [legs[rng.integers(2)]]
        rot2 = rot.copy()
        rot2[changed[0]] = quat.normalize(rng.normal(size=4))
        rot2[changed[0] + 1] = quat.normalize(rng.normal(size=4))
        changed.append(changed[0] + 1)
        full = forward_kinematics_pose(rot2, pos, parents)
        part = forward_kinematics_update(g_rot, g_pos, rot2, pos, parents, subtree_joints(parents, changed))
        assert np.array_equal(full[0], part[0]) and np.array_equal(full[1], part[1])
    # a wrong joint list (a subtree left out) is caught by the comparison: the test can fail
    rot2 = rot.copy()
    rot2[legs[0]] = quat.normalize(rng.normal(size=4))
    part = forward_kinematics_update(g_rot, g_pos, rot2, pos, parents, [legs[0]])
    assert not np.array_equal(forward_kinematics_pose(rot2, pos, parents)[1], part[1])


def test_single_pose_forward_kinematics_is_the_per_joint_definition_bit_for_bit(db):
    """One pose in plain floats: per joint g = g_parent * local and p = (p_parent + offset) + w t + u x t
    (numpy on one joint at a time, that order of sums), and the bulk form to rounding."""
    from lmm.kinematics import forward_kinematics

    parents = [int(p) for p in db.parents]
    rng = np.random.default_rng(4)
    for _ in range(50):
        rot, pos = _random_pose(rng, db.n_bones)
        want_rot, want_pos = rot.copy(), pos.copy()
        for j, p in enumerate(parents):
            if p >= 0:
                w, u = want_rot[p, :1], want_rot[p, 1:]
                t = 2.0 * np.cross(u, pos[j])
                want_pos[j] = want_pos[p] + pos[j] + w * t + np.cross(u, t)
                want_rot[j] = quat.mul(want_rot[p], rot[j])
        got_rot, got_pos = forward_kinematics_pose(rot, pos, PoseSkeleton(parents))
        assert np.array_equal(got_rot, want_rot) and np.array_equal(got_pos, want_pos)
        bulk_rot, bulk_pos = forward_kinematics(rot, pos, parents)
        np.testing.assert_allclose(got_pos, bulk_pos, rtol=0, atol=1e-12)
