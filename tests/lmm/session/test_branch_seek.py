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
