"""Inertialization: a jump is invisible at the transition and the offsets decay to zero."""
import numpy as np
import pytest

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


def _reference_decay(off, halflife, dt):
    """The numpy forms the fast decay replaces (lmm.springs on each part)."""
    from lmm.springs import decay_spring_damper_exact, decay_spring_damper_exact_quat
    pos, vel = decay_spring_damper_exact(off.positions, off.velocities, halflife, dt)
    rot, ang = decay_spring_damper_exact_quat(off.rotations, off.angular_velocities, halflife, dt)
    return pos, vel, rot, ang


def _reference_apply(off, positions, velocities, rotations, angular_velocities):
    return (positions + off.positions, velocities + off.velocities,
            quat.normalize(quat.mul(off.rotations, rotations)),
            off.angular_velocities + quat.mul_vec(off.rotations, angular_velocities))


def _random_offsets(rng, n):
    rot = quat.normalize(rng.normal(size=(n, 4)))
    rot[: n // 4] = quat.normalize(np.concatenate([np.ones((n // 4, 1)), rng.normal(size=(n // 4, 3)) * 1e-9], 1))
    rot[n // 4: n // 2, 0] *= -1.0           # negative w: the abs_ branch
    rot[n // 2] = (1.0, 0.0, 0.0, 0.0)       # exactly identity: the small-angle branch
    rot[n // 2 + 1] = (-0.0, 1.0, 0.0, 0.0)  # half a turn
    scale = rng.uniform(1e-6, 10.0, size=(n, 1))
    return Offsets(rng.normal(size=(n, 3)) * scale, rng.normal(size=(n, 3)) * scale, rot,
                   rng.normal(size=(n, 3)) * scale)


#: how far the decay's rotations may be from the reference's: the decay leaves out the exponential's final
#: normalisation and keeps the rotation vector its offsets were made from (see inertialize_decay)
CHAIN_TOLERANCE = 1e-12


def _rotation_error(g, w) -> float:
    """Largest component difference of two (J, 4) rotation arrays (q and -q are the same rotation)."""
    return float(np.minimum(np.abs(g - w), np.abs(g + w)).max())


def test_fast_decay_and_apply_equal_the_numpy_forms():
    """Positions, velocities and angular velocities bit for bit; rotations within CHAIN_TOLERANCE and of
    unit length to rounding; the apply bit for bit."""
    rng = np.random.default_rng(7)
    worst = 0.0
    for trial in range(200):
        n = int(rng.integers(4, 40))
        off = _random_offsets(rng, n)
        halflife = [0.0, 0.1, 0.05, float(rng.uniform(0.0, 1.0))][trial % 4]
        dt = [1 / 60, 1 / 30, 2.0, float(rng.uniform(0.0, 0.1))][trial % 4]
        got = inertialize_decay(off, halflife, dt)
        want = _reference_decay(off, halflife, dt)
        for g, w in zip((got.positions, got.velocities, got.angular_velocities), (want[0], want[1], want[3])):
            assert g.shape == w.shape and np.array_equal(g, w)
        assert got.rotations.shape == want[2].shape
        worst = max(worst, _rotation_error(got.rotations, want[2]))
        assert np.abs(np.sum(got.rotations ** 2, axis=1) - 1.0).max() <= 1e-15
        src = (rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), quat.normalize(rng.normal(size=(n, 4))),
               rng.normal(size=(n, 3)))
        for g, w in zip(inertialize_apply(off, *src), _reference_apply(off, *src)):
            assert g.shape == w.shape and np.array_equal(g, w)
    assert 0.0 < worst <= CHAIN_TOLERANCE


def test_decay_of_decayed_offsets_equals_the_numpy_forms_within_rounding():
    """A decay's result keeps its fields as views of stacked arrays, read as they are by the next decay,
    rotation vector included; chains of decays (with a field replaced or written in place between them)
    stay within rounding of the reference: the positions and velocities exactly, the rotations and
    angular velocities within CHAIN_TOLERANCE, and the first decay's angular velocities (nothing kept
    yet) bit for bit."""
    rng = np.random.default_rng(11)
    worst = 0.0
    for trial in range(40):
        n = int(rng.integers(4, 30))
        off = _random_offsets(rng, n)
        ref = (off.positions, off.velocities, off.rotations, off.angular_velocities)
        for k in range(6):
            off = inertialize_decay(off, 0.1, 1 / 60)
            ref = _reference_decay(Offsets(*ref), 0.1, 1 / 60)
            got = (off.positions, off.velocities, off.rotations, off.angular_velocities)
            assert np.array_equal(got[0], ref[0]) and np.array_equal(got[1], ref[1])
            if k == 0:
                assert np.array_equal(got[3], ref[3])
            for g, w in zip(got, ref):
                assert g.shape == w.shape
                # the same rotation: q and -q compare as equal
                diff = np.minimum(np.abs(g - w), np.abs(g + w)) if g.shape[1] == 4 else np.abs(g - w)
                worst = max(worst, float(diff.max()) / max(1.0, float(np.abs(w).max())))
            if k == 2:
                off.velocities[1] = 3.0          # in place: seen through the stacked array
                ref[1][1] = 3.0
            if k == 4:
                off.angular_velocities = off.angular_velocities * 0.5   # replaced: not the stacked view
                ref = (ref[0], ref[1], ref[2], ref[3] * 0.5)
    assert worst <= CHAIN_TOLERANCE


def test_a_long_chain_of_decays_stays_within_rounding_and_never_drifts():
    """Two seconds of ticks from offsets of every size: the kept rotation vectors never drift from the
    reference's logarithms (the error does not grow with the number of ticks)."""
    rng = np.random.default_rng(12)
    off = _random_offsets(rng, 23)
    off.angular_velocities *= 0.1
    ref = (off.positions, off.velocities, off.rotations, off.angular_velocities)
    errors = []
    for k in range(120):
        off = inertialize_decay(off, 0.2, 1 / 60)
        ref = _reference_decay(Offsets(*ref), 0.2, 1 / 60)
        d = np.minimum(np.abs(off.rotations - ref[2]), np.abs(off.rotations + ref[2]))
        errors.append(max(float(d.max()), float(np.abs(off.angular_velocities - ref[3]).max())))
    assert max(errors) <= CHAIN_TOLERANCE
    assert max(errors[60:]) <= max(max(errors[:60]), 1e-15)


def test_a_rotation_offset_past_the_threshold_takes_the_shorter_way_as_before():
    """A rotation vector that a decay pushes to 1.8 rad or more in some component (here a large angular
    velocity offset carries it past half a turn) is not kept: the logarithm wraps it to the shorter way
    round, as the reference does, so the chain stays with the reference (kept, it would decay the long
    way round)."""
    off = Offsets(np.zeros((1, 3)), np.zeros((1, 3)), np.array([[np.cos(0.75), np.sin(0.75), 0.0, 0.0]]),
                  np.array([[40.0, 0.0, 0.0]]))
    ref = (off.positions, off.velocities, off.rotations, off.angular_velocities)
    wrapped = False
    for k in range(30):
        kept = off._stack is not None and np.abs(off.positions.base[0, 1]).max() < 1.8
        off = inertialize_decay(off, 0.5, 1 / 60)
        ref = _reference_decay(Offsets(*ref), 0.5, 1 / 60)
        wrapped |= k > 0 and not kept
        d = np.minimum(np.abs(off.rotations - ref[2]), np.abs(off.rotations + ref[2]))
        assert float(d.max()) <= CHAIN_TOLERANCE and np.allclose(off.angular_velocities, ref[3], rtol=0, atol=1e-10)
    assert wrapped


def test_shown_pose_and_root_velocities_are_inertialize_apply_bit_for_bit():
    """The step's split of :func:`inertialize_apply` (pose now, bone 0's velocities in floats, every
    bone's velocities when a transition reads them) gives the same bits, after any number of decays."""
    from lmm.source_pose import SourcePose
    from lmm.inertialize import ShownPose, inertialize_apply_pose, inertialize_root_velocities

    rng = np.random.default_rng(7)
    off = inertialize_transition(*_pose(rng, 22), *_pose(rng, 22))
    src = _pose(rng, 22)                         # offsets not (yet) from a decay: separate arrays
    want = inertialize_apply(off, *src)
    vel0, ang0 = inertialize_root_velocities(off, src[1][0].tolist(), src[3][0].tolist())
    assert off._stack is None and vel0 == want[1][0].tolist() and list(ang0) == want[3][0].tolist()
    for _ in range(12):
        off = inertialize_decay(off, 0.1, 1 / 60)
        src = _pose(rng, 22)
        want = inertialize_apply(off, *src)
        pos, rot = inertialize_apply_pose(off, src[0], src[2])
        shown = ShownPose(pos, rot, off, SourcePose(src[0], src[2], src[1], src[3], np.zeros(2, bool)))
        vel0, ang0 = inertialize_root_velocities(off, src[1][0].tolist(), src[3][0].tolist())
        assert len(shown) == 4
        for a, b in zip(shown, want):
            assert a.tobytes() == b.tobytes()
        assert shown[1].tobytes() == want[1].tobytes() and shown[3].tobytes() == want[3].tobytes()
        assert vel0 == want[1][0].tolist() and list(ang0) == want[3][0].tolist()
        # the source pose given whole: its velocities (here made when read) are read only by a transition
        made = []
        source = SourcePose(src[0], src[2], lambda: made.append(1) or src[1], lambda: src[3], np.zeros(2, bool))
        later = ShownPose(pos, rot, off, source)
        assert made == []
        assert all(a.tobytes() == b.tobytes() for a, b in zip(later, want)) and made == [1]


def test_apply_without_normalising_unit_rotations_stays_unit():
    """Decayed offsets times rotations of unit length to float64 rounding need no normalisation: within a
    few units in the last place of the normalised product, of unit length to 1e-15, over a chain of ticks."""
    from lmm.inertialize import inertialize_apply_pose

    rng = np.random.default_rng(21)
    off = inertialize_transition(*_pose(rng, 23), *_pose(rng, 23))
    worst = 0.0
    for _ in range(60):
        off = inertialize_decay(off, 0.1, 1 / 60)
        src = _pose(rng, 23)
        pos, rot = inertialize_apply_pose(off, src[0], src[2], normalize=False)
        pos_n, rot_n = inertialize_apply_pose(off, src[0], src[2])
        assert np.array_equal(pos, pos_n)
        assert np.abs(np.sum(rot * rot, axis=1) - 1.0).max() <= 1e-15
        worst = max(worst, float(np.abs(rot - rot_n).max()))
    assert 0.0 < worst <= 1e-15


def test_pose_jumps_blend_out_slower_while_the_character_stands(db, features):
    """The offsets' halflife is inertialization_slow_halflife_s with the simulation object at rest and
    inertialization_halflife_s from 1 m/s, linear between (issue 34: a jump while standing or starting
    blends out without a jerk); 0 turns it off."""
    from lmm.character import INERTIALIZATION_SLOW_M_S
    from lmm.factory import make_controller
    from lmm.trajectory import SimulationState
    from lmm.tuning import Tuning
    tuning = Tuning()
    c = make_controller("mm", db, features, tuning, None, debug_comparison=False)

    def at(speed):
        st = c.sim.state
        c.sim = SimulationState((st[0], (speed, 0.0, 0.0), st[2], st[3], st[4]))
        return c._inertialization_halflife()

    fast, slow = tuning.inertialization_halflife_s, tuning.inertialization_slow_halflife_s
    assert slow > fast
    assert at(0.0) == pytest.approx(slow) and at(INERTIALIZATION_SLOW_M_S) == pytest.approx(fast)
    assert at(3.5) == pytest.approx(fast)
    assert at(0.5 * INERTIALIZATION_SLOW_M_S) == pytest.approx(0.5 * (slow + fast), abs=0.006)
    tuning.inertialization_slow_halflife_s = 0.0
    assert at(0.0) == fast
