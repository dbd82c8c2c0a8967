"""lmm.kinematics against per-frame, per-joint 4x4 homogeneous transforms."""
from __future__ import annotations

import numpy as np
import pytest

from lmm import kinematics, quat


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
