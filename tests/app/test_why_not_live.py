"""Why not and what if in the paused live studio, without a window: the live controller put back at a
shown tick's search (app.why_not_probe.live_before) plays the frame and has the stick released as long as
the run's own controller had at that tick, so the tick's search re-ranked under a scratch tuning is what
a reopened session's seeker gives, and a fresh search with that tuning (a branch from the tick) where the
tick searched; the live run goes on as if never asked."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from app.session import Session
from lmm.controller import InputState
from lmm.factory import make_controllers
from lmm.tuning import Tuning

WEIGHT = ("feature_weights", 4.0, "hip_velocity")


def _inputs():
    """Push, release past the idle delay (0.75 s), push again, release briefly, push."""
    push = [InputState(left_x=0.4 * np.sin(i / 25.0), left_y=1.0, camera_azimuth=0.2) for i in range(70)]
    rest = [InputState(camera_azimuth=0.2)] * 75
    return push + rest + push[:40] + rest[:20] + push[:45]


def test_a_paused_live_tick_is_asked_as_the_reopened_session_answers(dbf, tmp_path):
    from app.commands.session_common import open_with_database
    from app.playback import Playback
    from app.why_not_probe import ProbeUnavailable, TickProbe, live_before, session_before
    from lmm.session.player import SessionPlayer
    from lmm.session.schema import pose_fingerprint
    from lmm.session.seek import SessionSeeker
    from lmm.session.why_not import what_if

    db, features = dbf
    tuning = Tuning()
    tuning.name_database_entries({ch.name: float(w) for ch, w in zip(features.layout, features.weights)},
                                 db.tag_names)
    tuning.search_interval_s = 0.0         # every tick searches: each asked tick has a fresh search to equal
    controllers, _ = make_controllers(db, features, tuning, with_lmm=False)
    s = Session(db, features, tuning, controllers)
    s.start_recording(tmp_path / "take.bvh", ("mm",))
    mm = s.controllers["mm"]
    truth = {}                      # history tick -> (frame at its search, stick released s, idle set on)
    for inp in _inputs():
        frame = int(mm.frame)
        tick = s.step(inp).tick
        truth[tick] = (frame, mm.stick_released_s, mm.idle_set_active())
    playback = Playback(s.history, s.dt)
    studio = SimpleNamespace(session=s, playback=playback, inspected="mm")
    probe = TickProbe(studio)
    with pytest.raises(ProbeUnavailable, match="paused studio"):
        probe.what_if()                                   # live and running: nothing to ask
    playback.pause()
    asked = [2, 60, 71, 100, 115, 116, 144, 150, 190, 205, 215, s.tick]
    assert any(truth[t][2] for t in asked) and not all(truth[t][2] for t in asked)
    assert truth[115][2] and not truth[114][2]             # the idle set's first tick is asked
    probe.edit(*WEIGHT)
    live = {}
    for t in asked:
        with live_before(s, t, "mm") as held:
            c = held["mm"]
            assert (int(c.frame), c.stick_released_s, c.idle_set_active()) == truth[t], t
        playback.scrub_to(t)
        live[t] = probe.what_if()["result"]
    with pytest.raises(ProbeUnavailable, match="not in the rewind history"):
        with live_before(s, 1, "mm"):
            pass
    after = [InputState(left_x=-0.5, left_y=0.7)] * 70
    for inp in after:                                      # going on: the run never noticed
        s.step(inp)
    path = s.stop_recording().session
    session, db2, features2, _ = open_with_database(path)
    player = SessionPlayer(session, db2, features2)
    while not player.done:
        poses, _ = player.step()
    assert player.checked >= 5 and not player.mismatches
    assert pose_fingerprint(poses["mm"]) == pose_fingerprint(s.history.latest().snapshots["mm"].pose)
    seeker = SessionSeeker(session, db2, features2)
    for t in asked:
        snap = seeker.seek(t - 1)[1]["mm"]
        with session_before(seeker, t - 1, "mm") as held:
            scratch = seeker.tuning.copy()
            scratch.set(WEIGHT[0], WEIGHT[1], WEIGHT[2])
            reopened = what_if(held["mm"], snap.query, scratch)
        assert live[t].frames.tolist() == reopened.frames.tolist(), t
        assert np.array_equal(live[t].costs, reopened.costs), t
        assert snap.searched                               # a fresh search with the scratch tuning at that tick
        fresh = SessionSeeker(session, db2, features2, branch={WEIGHT[0]: {WEIGHT[2]: WEIGHT[1]}},
                              from_tick=t - 1).seek(t - 1)[1]["mm"]
        assert fresh.searched and fresh.candidates.frames.tolist() == live[t].frames.tolist(), t
        assert np.allclose(fresh.candidates.costs, live[t].costs, rtol=1e-5, atol=1e-6), t
    session.close()


def test_a_tuning_change_after_the_shown_tick_is_refused(dbf):
    from app.playback import Playback
    from app.why_not_probe import ProbeUnavailable, TickProbe

    db, features = dbf
    tuning = Tuning()
    controllers, _ = make_controllers(db, features, tuning, with_lmm=False)
    s = Session(db, features, tuning, controllers)
    for inp in _inputs()[:80]:
        s.step(inp)
    playback = Playback(s.history, s.dt)
    playback.pause()
    probe = TickProbe(SimpleNamespace(session=s, playback=playback, inspected="mm"))
    assert probe.what_if()["tick"] == 80
    tuning.set("transition_cost", 0.3)                      # a real slider move while paused
    with pytest.raises(ProbeUnavailable, match=r"the tuning changed after tick 80 \(transition_cost\)"):
        probe.what_if()
    s.step(InputState())                                    # a tick made with it can be asked
    playback.scrub_to(81)
    assert probe.what_if()["tick"] == 81
