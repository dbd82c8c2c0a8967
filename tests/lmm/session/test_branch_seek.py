"""Branch here, headless: a :class:`lmm.session.seek.SessionSeeker` given a branch shows at any tick, in any
order, the pose ``ab``'s arm B (:class:`lmm.session.player.SessionPlayer` with that branch) has there; and
``SessionSeeker.before`` leaves the seeker where it was."""
from __future__ import annotations

import numpy as np
import pytest

BRANCH = {"feature_weights": {"hip_velocity": 4.0}, "transition_cost": 0.5}
FROM = 90


@pytest.fixture(scope="module")
def session_path(tmp_path_factory):
    from app.cli import main as cli_main

    path = tmp_path_factory.mktemp("branch") / "s.lmmsession"
    assert cli_main(["run", "--controller", "mm", "--input", "builtin:random:1", "--seconds", "6",
                     "--session", str(path), "--quiet"]) == 0
    return path


def _arm_poses(session, db, features, branch):
    from lmm.session.player import SessionPlayer

    player = SessionPlayer(session, db, features, branch=branch, from_tick=FROM)
    out = []
    while not player.done:
        out.append(player.step()[0]["mm"].global_positions.copy())
    return out


def test_a_branched_seeker_is_abs_arm_b_at_any_tick(session_path):
    from app.commands.session_common import open_with_database
    from lmm.session.seek import SessionSeeker

    session, db, features, _ = open_with_database(session_path)
    arm_a, arm_b = _arm_poses(session, db, features, None), _arm_poses(session, db, features, BRANCH)
    seeker = SessionSeeker(session, db, features, branch=BRANCH, from_tick=FROM)
    differing = 0
    for tick in (300, 40, FROM, 200, FROM + 1, 340, 120, 10):     # forward, back, across the branch tick
        got = seeker.seek(tick)[0]["mm"].global_positions
        assert np.array_equal(got, arm_b[tick]), tick
        if tick < FROM:
            assert np.array_equal(got, arm_a[tick]), tick
        differing += not np.array_equal(got, arm_a[tick])
    assert differing >= 2                                  # the branch does change the motion after its tick
    session.close()


def test_before_puts_the_seeker_back(session_path):
    from app.commands.session_common import open_with_database
    from lmm.session.seek import SessionSeeker

    session, db, features, _ = open_with_database(session_path)
    seeker = SessionSeeker(session, db, features, every=60)
    seeker.seek(150)
    where, tuning = seeker.tick, seeker.tuning.to_dict()
    with seeker.before(70) as controllers:
        assert seeker.tick == 70 and controllers is seeker.controllers
        seeker.tuning.set("transition_cost", 3.0)           # what a what-if must not leave behind
    assert seeker.tick == where and seeker.tuning.to_dict() == tuning
    stepped = seeker.step()[0]["mm"].global_positions
    fresh = SessionSeeker(session, db, features, every=60)
    assert np.array_equal(stepped, fresh.seek(151)[0]["mm"].global_positions)
    session.close()


def test_a_what_if_inside_before_leaves_the_session_as_it_was(session_path):
    """What the studio's what-if does (new feature weights on the controller before a search, then put
    back) changes nothing later: the tick's own candidates, read after it, and the poses seeked after it
    are those of a seeker never asked."""
    from app.commands.session_common import open_with_database
    from lmm.session.seek import SessionSeeker
    from lmm.session.why_not import what_if

    session, db, features, _ = open_with_database(session_path)
    seeker, fresh = SessionSeeker(session, db, features), SessionSeeker(session, db, features)
    step = next(t for t in range(150, 300) if seeker.seek(t)[1]["mm"].searched)
    snap = seeker.seek(step)[1]["mm"]
    with seeker.before(step) as controllers:
        scratch = seeker.tuning.copy()
        scratch.set("feature_weights", 4.0, "hip_velocity")
        reranked = what_if(controllers["mm"], snap.query, scratch)
    assert snap.candidates.frames.tolist() == fresh.seek(step)[1]["mm"].candidates.frames.tolist()
    assert reranked.frames.tolist() != snap.candidates.frames.tolist()
    for tick in (step + 5, step + 70, 40):
        assert np.array_equal(seeker.seek(tick)[0]["mm"].global_positions,
                              fresh.seek(tick)[0]["mm"].global_positions), tick
    session.close()


@pytest.mark.parametrize("controller", ["mm", "lmm"])
def test_a_branch_from_a_checkpoint_is_the_branch_replayed_from_the_start(controller, tmp_path):
    """SessionSeeker.branched starts B's own controllers from A's checkpoint before the branch tick (a
    feature weight and a tag bias before it, a teleport after it; the checkpoint's tick is not the branch's):
    every tick shown, before and after the branch, is what a seeker replaying the branch from tick 0 shows
    (pose, frame, transition, cost, MM's ranked candidates), and its first tick costs at most a second."""
    import json

    from app.cli import main as cli_main
    from app.commands.session_common import open_with_database
    from lmm.session.seek import SessionSeeker

    events = [{"tick": 20, "kind": "tuning", "payload": {"field": "feature_weights", "channel": "left_foot_position",
                                                         "new": 1.4}},
              {"tick": 40, "kind": "tuning", "payload": {"field": "tag_bias", "channel": "run", "new": -0.3}},
              {"tick": 120, "kind": "teleport", "payload": {"position": [1.0, 0.0, 2.0], "yaw_deg": 30.0}},
              {"tick": 130, "kind": "tuning", "payload": {"field": "transition_cost", "new": 0.2}}]
    (tmp_path / "events.json").write_text(json.dumps({"events": events}))
    path = tmp_path / "s.lmmsession"
    assert cli_main(["run", "--controller", controller, "--input", "builtin:random:1", "--seconds", "5", "--events",
                     str(tmp_path / "events.json"), "--session", str(path), "--quiet"]) == 0
    session, db, features, weights = open_with_database(path)
    a = SessionSeeker(session, db, features, every=60, weights=weights)
    a.seek(200)                                           # A passed the branch: its checkpoints 0, 60 ... 180
    b = a.branched(BRANCH, FROM)
    fresh = SessionSeeker(session, db, features, weights=weights, branch=BRANCH, from_tick=FROM)
    differing = 0
    for i, tick in enumerate((FROM, FROM + 1, 150, 280, FROM + 30, 100, 40, 250)):
        pose_b, snap_b = (x[controller] for x in b.seek(tick))
        if i == 0:
            assert b.stepped <= 60, b.stepped            # from checkpoint 60, not from tick 0
        pose_f, snap_f = (x[controller] for x in fresh.seek(tick))
        assert np.array_equal(pose_b.global_positions, pose_f.global_positions), tick
        assert (snap_b.matched_frame, snap_b.transitioned) == (snap_f.matched_frame, snap_f.transitioned), tick
        assert np.array_equal(snap_b.current_cost, snap_f.current_cost, equal_nan=True), tick
        if controller == "mm":
            assert snap_b.candidates.frames.tolist() == snap_f.candidates.frames.tolist(), tick
        differing += not np.array_equal(pose_b.global_positions, a.seek(tick)[0][controller].global_positions)
    assert differing >= 2                                  # the branch does change the motion after its tick
    session.close()
