"""Two-bone IK and foot locking."""
import numpy as np
import pytest

from lmm import quat
from lmm.ik import FootLockState, foot_lock_update, solve_leg, toe_clear_ground, two_bone_ik


def _leg(bend=0.3):
    """Hip at the origin, thigh and shin of 0.45 m along -Y with a slight knee bend, global frames."""
    parents = [-1, 0, 1, 2]
    local_rot = np.array([[1.0, 0, 0, 0], quat.from_axis_angle(np.array([1.0, 0, 0]), bend),
                          [1.0, 0, 0, 0], [1.0, 0, 0, 0]])
    local_pos = np.array([[0, 1.0, 0], [0, -0.45, 0], [0, -0.45, 0], [0, -0.05, 0.15]])
    g_rot = np.zeros((4, 4))
    g_pos = np.zeros((4, 3))
    for j, p in enumerate(parents):
        if p < 0:
            g_rot[j], g_pos[j] = local_rot[j], local_pos[j]
        else:
            g_rot[j] = quat.mul(g_rot[p], local_rot[j])
            g_pos[j] = g_pos[p] + quat.mul_vec(g_rot[p], local_pos[j])
    return parents, g_rot, g_pos


@pytest.mark.parametrize("target", [[0.1, 0.25, 0.2], [0.0, 0.2, 0.0], [-0.2, 0.35, 0.1]])
def test_two_bone_ik_reaches_reachable_targets(target):
    parents, g_rot, g_pos = _leg()
    target = np.array(target)
    hip_new, knee_new = two_bone_ik(g_pos[0], g_pos[1], g_pos[2], target, g_rot[0], g_rot[1])
    # rebuild the chain with the new global rotations and the original bone vectors
    thigh = quat.inv_mul_vec(g_rot[0], g_pos[1] - g_pos[0])
    shin = quat.inv_mul_vec(g_rot[1], g_pos[2] - g_pos[1])
    knee = g_pos[0] + quat.mul_vec(hip_new, thigh)
    ankle = knee + quat.mul_vec(knee_new, shin)
    assert np.allclose(ankle, target, atol=1e-6)
    assert np.isclose(np.linalg.norm(knee - g_pos[0]), 0.45) and np.isclose(np.linalg.norm(ankle - knee), 0.45)


def test_unreachable_target_stretches_towards_it_without_nan():
    parents, g_rot, g_pos = _leg()
    target = g_pos[0] + np.array([0.0, -5.0, 0.0])
    hip_new, knee_new = two_bone_ik(g_pos[0], g_pos[1], g_pos[2], target, g_rot[0], g_rot[1])
    assert np.isfinite(hip_new).all() and np.isfinite(knee_new).all()
    thigh = quat.inv_mul_vec(g_rot[0], g_pos[1] - g_pos[0])
    shin = quat.inv_mul_vec(g_rot[1], g_pos[2] - g_pos[1])
    ankle = g_pos[0] + quat.mul_vec(hip_new, thigh) + quat.mul_vec(knee_new, shin)
    assert ankle[1] < g_pos[0][1] - 0.89  # (nearly) straight, pointing at the target


def test_solve_leg_puts_the_toe_on_target_and_keeps_the_foot_rotation():
    parents, g_rot, g_pos = _leg()
    target = g_pos[3] + np.array([0.05, 0.04, -0.03])
    new = solve_leg(g_pos, g_rot, (0, 1, 2, 3), target, np.array([0, 0, 1.0]), 0.0, None)
    assert np.allclose(new[2], g_rot[2])
    thigh = quat.inv_mul_vec(g_rot[0], g_pos[1] - g_pos[0])
    shin = quat.inv_mul_vec(g_rot[1], g_pos[2] - g_pos[1])
    ankle = g_pos[0] + quat.mul_vec(new[0], thigh) + quat.mul_vec(new[1], shin)
    toe = ankle + (g_pos[3] - g_pos[2])
    assert np.allclose(toe, target, atol=1e-6)


def test_toe_is_bent_up_above_the_ground():
    toe_rot = quat.from_axis_angle(np.array([1.0, 0, 0]), 0.4)  # +Z pointing down and forward
    new = toe_clear_ground(np.array([0, 0.02, 0]), toe_rot, np.array([0, 0, 1.0]), 0.15, 0.0)
    tip = np.array([0, 0.02, 0]) + 0.15 * quat.mul_vec(new, np.array([0, 0, 1.0]))
    assert tip[1] == pytest.approx(0.0, abs=1e-9)
    assert toe_clear_ground(np.array([0, 0.5, 0]), toe_rot, np.array([0, 0, 1.0]), 0.15, 0.0) is toe_rot


def test_foot_lock_locks_holds_unlocks_and_blends_back():
    s = FootLockState()
    dt = 1 / 60
    vel = np.zeros((2, 3))
    # contact begins on the left foot: locked where it is
    s, t = foot_lock_update(s, np.array([[0, 0.03, 0], [1, 0.3, 0]]), vel, [True, False], 0.2, 0.1, 0.02, dt)
    assert s.locked.tolist() == [True, False] and np.allclose(t[0], [0, 0.03, 0])
    # the animation slides 10 cm: the lock holds
    s, t = foot_lock_update(s, np.array([[0.1, 0.03, 0], [1, 0.3, 0]]), vel, [True, False], 0.2, 0.1, 0.02, dt)
    assert s.locked[0] and np.allclose(t[0], [0, 0.03, 0])
    # 25 cm: past the unlock radius, released without a pop, then blends to the animation
    anim = np.array([[0.25, 0.03, 0], [1, 0.3, 0]])
    s, t = foot_lock_update(s, anim, vel, [True, False], 0.2, 0.1, 0.02, dt)
    assert not s.locked[0] and np.allclose(t[0], [0, 0.03, 0]) and s.released[0]
    for _ in range(120):
        s, t = foot_lock_update(s, anim, vel, [True, False], 0.2, 0.1, 0.02, dt)
    assert not s.locked[0] and np.allclose(t[0], anim[0], atol=1e-4)  # no relock in the same contact
    # a locked toe below the foot height is raised to it
    s2, t2 = foot_lock_update(FootLockState(), np.array([[0, -0.01, 0], [0, 0, 0]]), vel, [True, True],
                              0.2, 0.1, 0.02, dt)
    assert t2[0][1] == pytest.approx(0.02)
