"""Per-frame cost work (issue 16): the faster forms give bit for bit the results of the forms they
replace (recordings stay byte-identical), and debug-only work is deferred until it is read."""
import numpy as np

from lmm import quat
from lmm.character import forward_kinematics_pose, forward_kinematics_update, subtree_joints
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
        c.root_position = rng.normal(size=3)
        c.root_rotation = quat.normalize(rng.normal(size=4))
        position, rotation = rng.normal(size=3), quat.normalize(rng.normal(size=4))
        toes = rng.normal(size=(2, 3))
        want = toes - (position + quat.mul_vec(rotation, quat.inv_mul_vec(c.root_rotation, toes - c.root_position)))
        got = np.array(c._root_shift([tuple(t) for t in toes.tolist()], position, rotation))
        assert np.array_equal(got, want)


def test_ground_offset_target_follows_the_take_of_the_source_frame(db, features):
    """The take's contact height is looked up once per take: the target for every frame, in order and
    jumping around, equals the direct lookup."""
    c = MotionMatchingController(db, features)
    c.tuning.ik_ground_calibration = True
    frames = list(range(0, len(db.contacts), 7)) + list(np.random.default_rng(1).integers(0, len(db.contacts), 300))
    heights = c._range_contact_height
    for f in frames:
        c.frame = int(f)
        h = float(heights[int(db.range_index(int(f)))])
        want = c.tuning.ik_foot_height_m - h if np.isfinite(h) else 0.0
        assert c._ground_offset_target() == want


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
