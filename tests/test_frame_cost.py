"""Per-frame cost work (issue 16): the faster forms give bit for bit the results of the forms they
replace (recordings stay byte-identical), and debug-only work is deferred until it is read."""
import numpy as np

from lmm import quat
from lmm.root_motion import LazyRootShift, root_shift
from lmm.kinematics import PoseSkeleton, pose_forward_kinematics, pose_forward_kinematics_update
from lmm.skeleton import subtree as subtree_joints
from lmm.controller import InputState
from lmm.data.inputs import builtin
from lmm.mm import MotionMatchingController

DT = 1 / 60


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


def test_one_rotation_spring_is_bit_identical_to_the_vectorised_form():
    """The plain-float path of simple_spring_damper_exact_quat (one rotation, scalar dt or a few horizons)
    against the numpy path it replaces, on the same arguments."""
    from lmm.springs import _spring_damper_exact_quat_arrays, simple_spring_damper_exact_quat

    rng = np.random.default_rng(7)
    for i in range(300):
        q = quat.normalize(rng.normal(size=4))
        goal = quat.normalize(rng.normal(size=4)) if i % 5 else q.copy()
        w = rng.normal(size=3) * (0.0 if i % 7 == 0 else 3.0)
        halflife = float(rng.uniform(0.0, 0.5))
        for dt in (1 / 60, float(rng.uniform(0, 2)), np.array([20, 40, 60]) / 60.0):
            got_q, got_w = simple_spring_damper_exact_quat(q, w, goal, halflife, dt)
            want_q, want_w = _spring_damper_exact_quat_arrays(q, w, goal, halflife, dt)
            assert got_q.shape == want_q.shape and np.array_equal(got_q, want_q)
            assert got_w.shape == want_w.shape and np.array_equal(got_w, want_w)


def test_root_shift_in_floats_is_bit_identical_to_the_numpy_form(db, features):
    c = MotionMatchingController(db, features)
    rng = np.random.default_rng(9)
    for _ in range(200):
        c._set_root(rng.normal(size=3).tolist(), quat.normalize(rng.normal(size=4)).tolist())
        position, rotation = rng.normal(size=3), quat.normalize(rng.normal(size=4))
        toes = rng.normal(size=(2, 3))
        want = toes - (position + quat.mul_vec(rotation, quat.inv_mul_vec(c.root_rotation, toes - c.root_position)))
        root = (c._root_position_t, c._root_rotation_t)
        got = np.array(root_shift(*root, [tuple(t) for t in toes.tolist()], position, rotation))
        assert np.array_equal(got, want)
        lazy = LazyRootShift(*root, [tuple(t) for t in toes.tolist()], position, rotation)
        assert np.array_equal(np.array([lazy[1], lazy[0]]), want[::-1])


def test_ground_offset_target_follows_the_take_of_the_source_frame(db, features):
    """The take's contact height is looked up once per take: the target for every frame, in order and
    jumping around, equals the direct lookup."""
    c = MotionMatchingController(db, features)
    c.tuning.ik_ground_calibration = True
    frames = list(range(0, len(db.contacts), 7)) + list(np.random.default_rng(1).integers(0, len(db.contacts), 300))
    heights = c.ground._range_heights
    for f in frames:
        c.frame = int(f)
        h = float(heights[int(db.range_index(int(f)))])
        want = c.tuning.ik_foot_height_m - h if np.isfinite(h) else 0.0
        assert c.ground.target(c.tuning, c._calibration_frame()) == want


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


def test_packed_rows_are_numpys_cast_bit_for_bit():
    """The pose arrays are packed by struct: the same bits as numpy's cast of the same floats, including
    values that round, overflow to infinity, underflow to zero or are NaN; new writable arrays each call,
    one per block, in the blocks' order and shapes."""
    from lmm.pose_rows import pack_rows as _pack_rows

    rng = np.random.default_rng(3)
    rows = [tuple(v) for v in (rng.standard_normal((23, 4)) * 10.0 ** rng.integers(-45, 45, (23, 4))).tolist()]
    rows[3] = (float("nan"), float("inf"), -1e300, 5e-324)
    rows[4] = (3.4028235677973366e38, -3.4028235e38 * 1.0000001, 1e-46, -0.0)
    narrow = [tuple(v) for v in rng.standard_normal((23, 3)).tolist()]
    for dtype in (np.float32, np.float64, np.float16):    # float16: numpy's conversion
        with np.errstate(over="ignore"):
            want = np.array(rows).astype(dtype), np.array(narrow).astype(dtype)
            got = _pack_rows(((rows, 4), (narrow, 3)), 23, dtype)
            again = _pack_rows(((rows, 4), (narrow, 3)), 23, dtype)
        assert len(got) == 2
        for g, w in zip(got, want):
            assert g.dtype == w.dtype and g.shape == w.shape and g.tobytes() == w.tobytes(), dtype
            assert g.flags.writeable and g.flags.c_contiguous
        assert not np.may_share_memory(got[0], got[1]) and not np.may_share_memory(got[0], again[0])


def test_rotation_distance_is_the_numpy_definition_bit_for_bit():
    """The sharp-input test's rotation rate: the angle between two rotations in plain floats is the numpy
    definition's, bit for bit (negative w, tiny and half-turn differences)."""

    rng = np.random.default_rng(8)
    for i in range(3000):
        a = rng.normal(size=4)
        a /= np.linalg.norm(a)
        kind = i % 4
        if kind == 0:
            b = -a                                            # the same rotation, other sign
        elif kind == 1:
            b = a + rng.normal(size=4) * 1e-10                # a tiny difference (the small branch)
        else:
            b = rng.normal(size=4)
            b /= np.linalg.norm(b)
        a, b = tuple(a.tolist()), tuple(b.tolist())
        want = np.linalg.norm(quat.angle_axis_difference(np.array(a), np.array(b)), axis=-1)
        assert quat.norm_scalar(quat.angle_axis_difference_scalar(a, b)) == want
