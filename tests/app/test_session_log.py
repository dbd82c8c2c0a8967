"""The studio's session log (app/session_log.py), headless: a recording that starts mid-session, with
tuning changes before and during it and a reset inside it, replays (``lmm-studio replay``) to the
studio's own BVH byte for byte, from the session's own start (the last reset)."""
from __future__ import annotations

import numpy as np
import pytest

from app.cli import main as cli_main
from app.session import Session
from lmm.controller import InputState
from lmm.factory import make_controllers
from lmm.session.reader import open_session
from lmm.tuning import Tuning



def _session(dbf):
    db, features = dbf
    tuning = Tuning()
    tuning.name_database_entries({ch.name: float(w) for ch, w in zip(features.layout, features.weights)},
                                 db.tag_names)
    controllers, _ = make_controllers(db, features, tuning, with_lmm=False)
    return Session(db, features, tuning, controllers)


def _drive(s, n, turn):
    for i in range(n):
        s.step(InputState(left_x=turn * (i % 40) / 40.0, left_y=1.0, walk=i % 90 > 60, camera_azimuth=0.3))


def test_a_recording_mid_session_replays_to_the_same_bvh(dbf, tmp_path, capsys):
    s = _session(dbf)
    _drive(s, 50, 1.0)
    s.reset()                                            # the log starts here: the first 50 ticks are gone
    _drive(s, 70, -1.0)
    s.tuning.set("run_forward_speed_m_s", 2.0)           # before the recording: in its session too
    s.tuning.set("feature_weights", 0.5, "hip_velocity")
    _drive(s, 40, 0.5)
    paths = s.start_recording(tmp_path / "take.bvh", ("mm",))
    assert s.log.tick == 110 and s.tick == 110          # the character is mid-walk, far from the origin
    _drive(s, 45, 1.0)
    s.tuning.set("tag_bias", 0.5, "walk")
    _drive(s, 30, -0.5)
    s.reset()                                            # a reset during the recording: a reset event
    _drive(s, 50, 1.0)
    result = s.stop_recording()
    assert result.frames == 125 and result.session == tmp_path / "take.lmmsession"
    assert result.message.endswith("; session take.lmmsession")
    f = open_session(result.session)
    assert f.ticks == 235 and f.recording_from == 110 and f.meta["closed"]
    kinds = [(e.tick, e.kind) for e in f.events]
    assert kinds == [(70, "tuning"), (70, "tuning"), (155, "tuning"), (185, "reset")], kinds
    assert f.start_tuning().run_forward_speed_m_s == Tuning().run_forward_speed_m_s
    f.close()
    again = tmp_path / "again.bvh"
    rc = cli_main(["replay", str(result.session), "--record", str(again)])
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert "fingerprints match" in out
    assert again.read_bytes() == paths["mm"].read_bytes()
    # the log goes on after the recording: a second one holds the whole stretch since the reset at 50
    paths2 = s.start_recording(tmp_path / "take.bvh", ("mm",))
    assert paths2["mm"].name == "take_001.bvh"
    _drive(s, 20, 0.2)
    result2 = s.stop_recording()
    assert result2.session.name == "take_001.lmmsession" and open_session(result2.session).recording_from == 235
    assert cli_main(["replay", str(result2.session), "--record", str(tmp_path / "again2.bvh")]) == 0
    assert (tmp_path / "again2.bvh").read_bytes() == paths2["mm"].read_bytes()


def test_an_empty_recording_leaves_no_session_and_new_weights_end_one(dbf, tmp_path):
    s = _session(dbf)
    s.start_recording(tmp_path / "take.bvh", ("mm",))
    assert (tmp_path / "take.lmmsession").exists()
    assert s.stop_recording().session is None and list(tmp_path.iterdir()) == []
    s.start_recording(tmp_path / "take.bvh", ("mm",))
    _drive(s, 10, 1.0)
    db, features = dbf
    s.controllers["mm"] = make_controllers(db, features, s.tuning, with_lmm=False)[0]["mm"]   # as new weights do
    s.reset()
    _drive(s, 10, 1.0)
    result = s.stop_recording()
    assert "ends at tick 10: the controllers changed" in result.message
    assert open_session(result.session).ticks == 10


def test_a_reopened_session_shows_any_tick_and_goes_live_again(dbf, tmp_path):
    """app/review.py without a window: the history covers the whole session, a picked tick is the recorded
    one (its fingerprint, or the live history's pose), Play moves on a tick a frame, live gives the live
    characters back."""
    from types import SimpleNamespace

    from app.playback import Playback
    from app.review import open_recorded_session
    from lmm.session.schema import pose_fingerprint

    s = _session(dbf)
    s.start_recording(tmp_path / "take.bvh", ("mm",))
    _drive(s, 60, 1.0)
    s.tuning.set("feature_weights", 0.5, "hip_velocity")
    _drive(s, 130, -0.5)
    path = s.stop_recording().session
    shown = {t: s.history.get(t).snapshots["mm"].pose for t in range(s.tick - 30, s.tick + 1)}
    live = s.controllers["mm"]
    errors = SimpleNamespace(show=lambda *a: pytest.fail(str(a)), inform=lambda *a: None)
    studio = SimpleNamespace(session=s, playback=Playback(s.history, s.dt), errors=errors, reviewed=None)
    assert open_recorded_session(studio, path)
    h, p = s.history, studio.playback
    assert (h.oldest_tick, h.newest_tick, p.mode) == (1, 190, "SESSION") and s.controllers["mm"] is not live
    f = open_session(path)
    for tick in (170, 60, 185, 119, 1, 178):
        p.scrub_to(tick)
        pose = p.displayed_tick().snapshots["mm"].pose
        if (tick - 1, "mm") in f.fingerprints:
            assert pose_fingerprint(pose) == f.fingerprints[(tick - 1, "mm")]
        if tick in shown:
            assert pose_fingerprint(pose) == pose_fingerprint(shown[tick])
    speeds = h.window("mm", "speed", 178, 5)              # the plots: the ticks stepped on the way
    assert speeds.shape == (5,) and not np.isnan(speeds).any()
    p.resume()
    assert p.ticks_due(1 / 60) == 0 and p.displayed_tick().tick == 179
    p.go_live()
    assert s.controllers["mm"] is live and s.history is not h and p.live and studio.reviewed is None


def test_open_of_a_bad_session_is_one_line(tmp_path, capsys):
    """lmm-studio --open is checked before any window (no display needed): one line, exit 1."""
    bad = tmp_path / "bad.lmmsession"
    bad.write_bytes(b"SQLite format 3\0" + b"\0" * 50)
    for path in (bad, tmp_path / "missing.lmmsession"):
        assert cli_main(["--open", str(path)]) == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith("lmm-studio: error: ") and str(path) in err and "\n" not in err, err
