"""Inertialization: a jump is invisible at the transition and the offsets decay to zero."""
import numpy as np

from lmm import quat
from lmm.inertialize import Offsets, inertialize_apply, inertialize_decay, inertialize_transition


def _pose(rng, n=5):
    return (rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), quat.normalize(rng.normal(size=(n, 4))),
            rng.normal(size=(n, 3)))


def test_transition_reproduces_the_shown_pose_then_decays():
    rng = np.random.default_rng(0)
    shown, dst = _pose(rng), _pose(rng)
    off = inertialize_transition(*shown, *dst)
    pos, vel, rot, ang = inertialize_apply(off, dst[0], dst[1], dst[2], dst[3])
    assert np.allclose(pos, shown[0]) and np.allclose(vel, shown[1]) and np.allclose(ang, shown[3])
    assert np.allclose(np.abs(np.sum(rot * shown[2], axis=-1)), 1.0)
    later = inertialize_decay(off, 0.1, 2.0)
    assert np.abs(later.positions).max() < 1e-6 and np.abs(later.velocities).max() < 1e-4
    assert np.allclose(np.abs(later.rotations[:, 0]), 1.0, atol=1e-9)


def test_zero_halflife_snaps_and_offsets_shrink_monotonically():
    rng = np.random.default_rng(1)
    off = inertialize_transition(*_pose(rng), *_pose(rng))
    off.velocities[:] = 0.0
    off.angular_velocities[:] = 0.0
    snapped = inertialize_decay(off, 0.0, 1 / 60)
    assert np.abs(snapped.positions).max() < 1e-9
    sizes = []
    o = off
    for _ in range(30):
        o = inertialize_decay(o, 0.1, 1 / 60)
        sizes.append(np.abs(o.positions).max())
    assert all(b <= a + 1e-12 for a, b in zip(sizes, sizes[1:]))


def test_output_is_continuous_across_a_transition():
    """Position keeps moving at the shown velocity through the jump (first-order continuity)."""
    shown_pos, shown_vel = np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0]])
    dst_pos, dst_vel = np.array([[0.5, 0.0, 0.0]]), np.array([[-1.0, 0.0, 0.0]])
    rot = np.array([[1.0, 0, 0, 0]])
    off = inertialize_transition(shown_pos, shown_vel, rot, np.zeros((1, 3)), dst_pos, dst_vel, rot, np.zeros((1, 3)))
    dt = 1e-4
    off2 = inertialize_decay(off, 0.1, dt)
    pos, *_ = inertialize_apply(off2, dst_pos + dst_vel * dt, dst_vel, rot, np.zeros((1, 3)))
    assert np.allclose(pos, shown_pos + shown_vel * dt, atol=1e-6)
    assert isinstance(Offsets.zeros(3).rotations, np.ndarray)
