"""The character pipeline's tick (lmm/character.py): the pose it returns is the forward kinematics of its
local pose, the per-leg update gives the generic form's bits, the ghost is made when read."""
import numpy as np

from lmm.controller import InputState
from lmm.data.inputs import builtin
from lmm.kinematics import PoseSkeleton, pose_forward_kinematics
from lmm.mm import MotionMatchingController

DT = 1 / 60


def forward_kinematics_pose(rot, pos, parents):
    """:func:`pose_forward_kinematics` as two arrays."""
    g, p = pose_forward_kinematics(rot, pos, parents)
    return np.array(g), np.array(p)


def test_ghost_is_computed_on_first_read_and_matches_the_source_pose(db, features):
    c = MotionMatchingController(db, features)
    log = builtin("zigzag", 2.0)
    for i in range(30):
        _, snap = c.step(log.at(i * DT), DT)
    assert callable(snap.__dict__["_lazy_matched_pose_positions"])  # not computed yet
    ghost = snap.matched_pose_positions
    assert ghost.dtype == np.float32 and ghost.shape == (db.n_bones, 3)
    assert snap.matched_pose_positions is ghost  # computed once
    src = c.source
    rot, pos = src.rotations.copy(), src.positions.copy()
    rot[0], pos[0] = c.root_rotation, c.root_position
    assert np.array_equal(ghost, forward_kinematics_pose(rot, pos, c.parents)[1].astype(np.float32))
    _, snap2 = c.step(InputState(), DT)
    assert snap.matched_pose_positions is ghost  # a later tick does not touch an earlier snapshot


def test_world_pose_arrays_match_forward_kinematics_of_the_returned_local_pose(db, features):
    """The pose block's global arrays are the forward kinematics of its local arrays (legs included)."""
    c = MotionMatchingController(db, features)
    log = builtin("zigzag", 3.0)
    locked_seen = 0
    for i in range(150):
        pose, snap = c.step(log.at(i * DT), DT)
        locked_seen += int(snap.foot_locked.sum())
    src = c.shown
    local_rot, local_pos, g_rot, g_pos, locked = c._world_pose(src[2], src[0], c.source.contacts,
                                                               (c.root_position.copy(), c.root_rotation.copy()), DT)
    full = forward_kinematics_pose(local_rot, local_pos, c.parents)
    assert np.array_equal(full[0], g_rot) and np.array_equal(full[1], g_pos)
    assert locked.dtype == bool and locked.shape == (2,) and locked_seen > 0


def _world_pose_state(c):
    return (c.foot_lock.copy(), c._prev_toe, c.ground.offset, c.ground.velocity, c.ground._span)


def _set_world_pose_state(c, state):
    c.foot_lock = state[0].copy()
    c._prev_toe, c.ground.offset, c.ground.velocity, c.ground._span = state[1:]


def test_fused_leg_update_and_float32_arrays_equal_the_generic_float64_form(db, features):
    """Per tick: the per-leg update (:func:`lmm.kinematics.leg_update`) gives the bits of the generic
    local-from-global loop plus subtree forward kinematics, and the float32 arrays the step asks for are the
    float64 arrays cast; the foot lock state advances the same."""
    c = MotionMatchingController(db, features)
    log = builtin("zigzag", 4.0)
    generic = PoseSkeleton(c.parents, c.leg_chains)
    fused = PoseSkeleton(c.parents, c.leg_chains)
    assert fused.legs is not None
    generic.legs = None
    both_legs = 0
    for i in range(200):
        c.step(log.at(i * DT), DT)
        src, root = c.shown, (c.root_position.copy(), c.root_rotation.copy())
        state = _world_pose_state(c)
        c._fk_plan = generic
        want = c._world_pose(src[2], src[0], c.source.contacts, root, DT)
        want_state = _world_pose_state(c)
        _set_world_pose_state(c, state)
        c._fk_plan = fused
        got64 = c._world_pose(src[2], src[0], c.source.contacts, root, DT)
        _set_world_pose_state(c, state)
        got = c._world_pose(src[2], src[0], c.source.contacts, root, DT, np.float32)
        got_state = _world_pose_state(c)
        for a, b, b64 in zip(want[:4], got[:4], got64[:4]):
            assert np.array_equal(a, b64)
            assert b.dtype == np.float32 and np.array_equal(a.astype(np.float32), b)
        assert np.array_equal(want[4], got[4])
        assert want_state[1:] == got_state[1:]
        for name in ("locked", "lock_position", "offset_position", "offset_velocity", "lowest_animated"):
            assert np.array_equal(getattr(want_state[0], name), getattr(got_state[0], name))
        _set_world_pose_state(c, state)
        both_legs += int(not np.array_equal(want[0][c.leg_chains[0][0]], src[2][c.leg_chains[0][0]])
                         and not np.array_equal(want[0][c.leg_chains[1][0]], src[2][c.leg_chains[1][0]]))
    assert both_legs > 50  # the legs were solved (their local rotations changed)
