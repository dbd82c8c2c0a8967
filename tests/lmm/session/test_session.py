"""Sessions (issue 33, headless): ``run --session/--events``, ``replay``, ``trace`` and ``ab`` end to end.

Short sessions on the default data: a 15 s run with 34 tuning changes and five actions from an events file
is replayed bit for bit (the BVH and every fingerprint) for MM and LMM; a branch differs only after its
tick; a run killed at any moment leaves no file or one that replays to its last committed tick; hostile
files give one line and exit 1; the trace's columns and values are the run's own snapshots.
"""
from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "tests" / "corpus"))
import session_files  # noqa: E402

SECONDS = 15
FPS = 60


def cli(capsys, *argv) -> tuple[int, str, str]:
    """``lmm-studio ARGV`` in this process: (exit code, stdout, stderr)."""
    rc = cli_main([str(a) for a in argv])
    out = capsys.readouterr()
    return rc, out.out, out.err


def _events() -> dict:
    """34 tuning changes (plain fields, feature weights, tag biases, a boolean) and five actions over 15 s."""
    changes = [("search_interval_s", None, 0.05), ("transition_cost", None, 0.3), ("stick_deadzone", None, 0.25),
               ("feature_weights", "left_foot_position", 1.5), ("inertialization_halflife_s", None, 0.15),
               ("tag_bias", "walk", -0.2), ("feature_weights", "trajectory_position", 1.2),
               ("exclude_current_window_frames", None, 30), ("ik_enabled", None, False),
               ("run_forward_speed_m_s", None, 3.0), ("feature_weights", "hip_velocity", 0.5)]
    events, tick = [], 20
    for i in range(34):
        field, channel, value = changes[i % len(changes)]
        if i >= len(changes):       # the second and third round move the values again
            value = (not value) if isinstance(value, bool) else (value + 0.01 * (i // len(changes))
                                                                 if isinstance(value, float) else value + i // 11)
        payload = {"field": field, "new": value}
        if channel:
            payload["channel"] = channel
        events.append({"tick": tick, "kind": "tuning", "payload": payload})
        tick += 25
    actions = [{"tick": 150, "kind": "teleport", "payload": {"position": [2.0, 0.0, -1.0], "yaw_deg": 45.0}},
               {"tick": 300, "kind": "reset", "payload": {}},
               {"tick": 420, "kind": "command", "payload": {"id": "camera_follow"}},
               {"tick": 600, "kind": "reset", "payload": {"position": [0.0, 0.0, 3.0], "rotation": [0.0, 0.0, 1.0, 0.0]}},
               {"tick": 750, "kind": "teleport", "payload": {"position": [-1.0, 0.0, 0.0]}}]
    merged = sorted(events + actions, key=lambda e: e["tick"])
    return {"events": merged}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """{controller: (session, bvh, events file)} of a 15 s run with the events, recorded."""
    folder = tmp_path_factory.mktemp("sessions")
    events = folder / "events.json"
    events.write_text(json.dumps(_events()))
    out = {}
    for controller in ("mm", "lmm"):
        session, bvh = folder / f"{controller}.lmmsession", folder / f"{controller}.bvh"
        rc = cli_main(["run", "--controller", controller, "--input", "builtin:random:1", "--seconds", str(SECONDS),
                       "--events", str(events), "--session", str(session), "--record", str(bvh), "--quiet"])
        assert rc == 0
        out[controller] = (session, bvh, events)
    return out


@pytest.mark.parametrize("controller", ["mm", "lmm"])
def test_replay_reproduces_the_run_bit_for_bit(recorded, controller, tmp_path, capsys):
    session, bvh, _ = recorded[controller]
    con = sqlite3.connect(session)
    kinds = [k for (k,) in con.execute("SELECT kind FROM events ORDER BY seq")]
    fingerprints = con.execute("SELECT count(*) FROM fingerprints").fetchone()[0]
    con.close()
    assert kinds.count("tuning") >= 30 and kinds.count("reset") == 2 and kinds.count("teleport") == 2
    assert fingerprints == SECONDS            # one a second, the last tick included
    again = tmp_path / "again.bvh"
    metrics = tmp_path / "m.json"
    rc, out, err = cli(capsys, "replay", session, "--record", again, "--metrics-json", metrics)
    assert rc == 0 and err == "", err
    assert f"all {SECONDS} fingerprints match" in out
    assert again.read_bytes() == bvh.read_bytes()     # cmp
    report = json.loads(metrics.read_text())
    assert report["fingerprints"] == {"checked": SECONDS, "differing": 0, "unexpected": []}
    assert report["controllers"][controller]["ticks"] == SECONDS * FPS


def test_a_replay_that_differs_names_the_tick(recorded, tmp_path, capsys):
    """A recorded fingerprint that the replay does not reproduce: one line naming its tick, exit 1."""
    copy = tmp_path / "tampered.lmmsession"
    copy.write_bytes(recorded["mm"][0].read_bytes())
    con = sqlite3.connect(copy)
    con.execute("UPDATE fingerprints SET pose = ? WHERE tick = ?", ("0" * 32, 7 * FPS - 1))
    con.commit()
    con.close()
    rc, out, err = cli(capsys, "replay", copy)
    assert rc == 1 and err.count("\n") == 1 and f"at tick {7 * FPS - 1} " in err and "1 of 15" in err, err


def test_a_session_changes_nothing_in_the_run(tmp_path, capsys):
    """``run --session`` without events records the same bytes as a plain ``run``."""
    plain, kept = tmp_path / "plain.bvh", tmp_path / "kept.bvh"
    base = ["run", "--controller", "mm", "--input", "builtin:circle", "--seconds", "10", "--quiet"]
    assert cli(capsys, *base, "--record", plain)[0] == 0
    assert cli(capsys, *base, "--record", kept, "--session", tmp_path / "s.lmmsession")[0] == 0
    assert plain.read_bytes() == kept.read_bytes()


def test_a_branch_differs_only_after_its_tick(recorded, tmp_path, capsys):
    session = recorded["mm"][0]
    preset = tmp_path / "b.json"
    preset.write_text(json.dumps({"feature_weights": {"trajectory_direction": 3.0}}))
    rc, out, err = cli(capsys, "ab", session, "--tuning", preset, "--from-tick", 200, "--json", tmp_path / "ab.json",
                       "--report", tmp_path / "plots")
    assert rc == 0, err
    report = json.loads((tmp_path / "ab.json").read_text())
    diff = report["controllers"]["mm"]["pose_difference_m"]
    assert diff["before_branch_max"] == 0.0 and diff["first_differing_tick"] >= 200 and diff["after_branch_max"] > 0
    assert report["arm_a"]["fingerprints_differing"] == 0
    for arm in ("a", "b"):
        assert report["controllers"]["mm"][arm]["ticks"] == SECONDS * FPS
    assert report["controllers"]["mm"]["a"] != report["controllers"]["mm"]["b"]
    assert (tmp_path / "plots" / "ab_mm.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rc, out, err = cli(capsys, "replay", session, "--tuning", preset, "--from-tick", 200)
    assert rc == 0 and "fingerprints before the branch match" in out, err


def test_a_killed_run_leaves_no_file_or_one_that_replays(tmp_path, capsys):
    """SIGKILL of ``run --session`` (paced to the wall clock) at several moments, one within its first
    0.5 s: no file, or one that opens and replays to its last committed tick."""
    procs = []
    for i, delay in enumerate((0.3, 0.45, 2.4, 3.3)):
        out = tmp_path / f"killed{i}.lmmsession"
        p = subprocess.Popen([sys.executable, "-m", "app.cli", "run", "--input", "builtin:random:1", "--seconds", "30",
                              "--realtime", "--session", str(out), "--quiet"], cwd=ROOT, env=dict(os.environ))
        procs.append((p, delay, out))
    start = time.monotonic()
    for p, delay, _ in sorted(procs, key=lambda x: x[1]):
        time.sleep(max(0.0, start + delay - time.monotonic()))
        p.send_signal(signal.SIGKILL)
    from lmm.session.reader import open_session
    kept = 0
    for p, delay, out in procs:
        p.wait()
        if not out.exists():
            continue
        ticks = open_session(out).ticks
        rc, text, err = cli(capsys, "replay", out)
        assert rc == 0 and err == "" and f"replayed {ticks} ticks" in text, (delay, err)
        kept += ticks > 0
    assert kept >= 1          # the later kills leave sessions with ticks in them


@pytest.mark.parametrize("name", sorted(session_files.BAD))
def test_hostile_sessions_give_one_line(recorded, tmp_path, capsys, name):
    made = session_files.make_bad(recorded["mm"][0], tmp_path, only={name})
    start = time.perf_counter()
    rc, out, err = cli(capsys, "replay", made[name])
    lines = [line for line in err.splitlines() if line.strip()]
    assert rc == 1 and len(lines) == 1 and "Traceback" not in err, err
    assert name in lines[0] and lines[0].startswith("lmm-studio replay: error: ")
    word = session_files.BAD[name][1]
    assert word is None or word.lower() in lines[0].lower(), lines[0]
    assert time.perf_counter() - start < 20


def test_a_session_of_other_networks_is_refused(recorded, tmp_path, capsys):
    copy = tmp_path / "other_weights.lmmsession"
    copy.write_bytes(recorded["lmm"][0].read_bytes())
    con = sqlite3.connect(copy)
    con.execute("UPDATE controllers SET weights_sha256 = ? WHERE kind = 'lmm'", ("ab" * 32,))
    con.commit()
    con.close()
    rc, out, err = cli(capsys, "replay", copy)
    assert rc == 1 and err.count("\n") == 1 and "networks" in err and "abababababab" in err and str(copy) in err


def test_a_journal_left_by_a_killed_run_does_not_touch_a_new_session(tmp_path, capsys):
    """A new session at the path of a killed one: the old hot journal beside it is not rolled into it."""
    path = tmp_path / "again.lmmsession"
    path.with_name(path.name + "-journal").write_bytes(b"\xd9\xd5\x05\xf9\x20\xa1\x63\xd7" + bytes(4088))
    rc, _, err = cli(capsys, "run", "--input", "builtin:circle", "--seconds", "2", "--session", path, "--quiet")
    assert rc == 0, err
    rc, out, err = cli(capsys, "replay", path)
    assert rc == 0 and "replayed 120 ticks" in out, err


def test_another_program_version_is_a_warning(recorded, tmp_path, capsys):
    copy = tmp_path / "old.lmmsession"
    copy.write_bytes(recorded["mm"][0].read_bytes())
    con = sqlite3.connect(copy)
    con.execute("UPDATE meta SET value = '\"0.0.1\"' WHERE key = 'program_version'")
    con.commit()
    con.close()
    rc, out, err = cli(capsys, "replay", copy)
    assert rc == 0 and "fingerprints match" in out
    assert err.startswith("warning: ") and err.count("\n") == 1 and "0.0.1" in err and str(copy) in err


def test_bad_events_files_are_refused_before_the_run(tmp_path, capsys):
    cases = {"unknown_field": [{"tick": 1, "kind": "tuning", "payload": {"field": "nope", "new": 1}}],
             "after_the_run": [{"tick": 10 ** 6, "kind": "reset", "payload": {}}],
             "out_of_order": [{"tick": 9, "kind": "reset", "payload": {}}, {"tick": 3, "kind": "reset", "payload": {}}],
             "out_of_range": [{"tick": 1, "kind": "tuning", "payload": {"field": "top_k", "new": 1000}}]}
    for name, events in cases.items():
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps({"events": events}))
        rc, _, err = cli(capsys, "run", "--input", "builtin:circle", "--seconds", "1", "--events", path,
                         "--session", tmp_path / f"{name}.lmmsession", "--quiet")
        assert rc == 1 and err.count("\n") == 1 and path.name in err, (name, err)
        assert not (tmp_path / f"{name}.lmmsession").exists()


def test_outputs_never_overwrite_the_inputs(recorded, tmp_path, capsys):
    session, _, events = recorded["mm"]
    before = session.read_bytes()
    alias = tmp_path / "same.csv"
    os.link(session, alias)                  # the session under another name: still the input
    for argv in (["replay", session, "--record", session], ["trace", session, "--out", alias],
                 ["ab", session, "--tuning", events, "--json", events]):
        rc, _, err = cli(capsys, *argv)
        assert rc == 1 and "overwrite" in err and err.count("\n") == 1, err
    assert session.read_bytes() == before


def test_trace_loads_in_pandas_with_the_documented_columns_and_the_runs_own_snapshots(db, features, tmp_path,
                                                                                    capsys):
    """A session made through the API while its snapshots are kept: its trace loads in pandas (CSV, and parquet
    where pyarrow is installed) with the columns lmm/session/trace.py documents, and holds the snapshots' values."""
    import math
    import re

    import numpy as np
    import pandas as pd

    from lmm.data.inputs import open_input
    from lmm.factory import make_controller
    from lmm.runner import run_headless
    from lmm.session import trace
    from lmm.session.player import SessionRecorder
    from lmm.session.writer import SessionWriter
    from lmm.tuning import Tuning

    tuning = Tuning()
    tuning.name_database_entries({ch.name: float(w) for ch, w in zip(features.layout, features.weights)},
                                 db.tag_names)
    controller = make_controller("mm", db, features, tuning)
    path = tmp_path / "api.lmmsession"
    writer = SessionWriter(path, fps=FPS, db=db, manifest=None, controllers={"mm": controller}, tuning=tuning,
                           start={"input": "builtin:zigzag", "seconds": 4.0, "reset": {}})
    session = SessionRecorder(tuning, {"mm": controller}, [], writer)
    seen = []                               # one entry per step, in order

    def keep(pose, snap):
        seen.append({"frame": int(snap.matched_frame), "root": pose.global_positions[0].astype(float).tolist(),
                     "contacts": [bool(c) for c in snap.foot_contacts], "transitioned": bool(snap.transitioned),
                     "searched": bool(snap.searched), "best_cost": float(snap.best_cost),
                     "current_cost": float(snap.current_cost), "left_x": float(snap.input.left_x)})

    run_headless(controller, open_input("builtin:zigzag", 4.0), 4.0, dt=1.0 / FPS, on_step=keep,
                 before_step=session.before_step, after_step=session.after_step)
    session.close()
    # the documented names, in the order the docstring first names them, are the columns (cost_<channel>: one
    # per feature channel)
    documented = dict.fromkeys(re.findall(r"``(\w+|cost_<channel>)``", trace.__doc__))
    channels = [f"cost_{c}" for c in features.names]
    expected = [c for name in documented for c in (channels if name == "cost_<channel>" else [name])]
    assert expected == trace.columns(features.names)
    out = tmp_path / "t.csv"
    rc, text, err = cli(capsys, "trace", path, "--out", out)
    assert rc == 0, err
    frames = {"csv": pd.read_csv(out)}
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        pass
    else:
        assert cli(capsys, "trace", path, "--out", tmp_path / "t.parquet")[0] == 0
        frames["parquet"] = pd.read_parquet(tmp_path / "t.parquet")
    for kind, df in frames.items():
        assert list(df.columns) == expected, kind
        assert len(df) == len(seen) == 4 * FPS, kind
        assert (df["tick"] == np.arange(len(df))).all() and (df["controller"] == "mm").all(), kind
        assert np.allclose(df["time_s"], (df["tick"] + 1) / FPS, rtol=0, atol=1e-12), kind
        # the channels split the played pose's cost (summed here in another order than the float32 total)
        assert np.allclose(df[channels].sum(axis=1), df["current_cost"], rtol=1e-5, atol=1e-6), kind
        assert (df["nn_frame"] == -1).all() and df["nn_cost"].isna().all(), kind      # MM: no LMM columns
        for i in (0, 1, 37, 120, len(df) - 1):
            want, row = seen[i], df.iloc[i]
            assert int(row["frame"]) == want["frame"], (kind, i)
            assert row["clip"] == db.range_names[int(db.range_index(want["frame"]))], (kind, i)
            assert [float(row[k]) for k in ("root_x", "root_y", "root_z")] == want["root"], (kind, i)
            assert [bool(row["contact_left"]), bool(row["contact_right"])] == want["contacts"], (kind, i)
            assert bool(row["transitioned"]) == want["transitioned"] and bool(row["searched"]) == want["searched"]
            assert float(row["left_x"]) == want["left_x"], (kind, i)
            for cost in ("best_cost", "current_cost"):      # exact (CSV: repr), NaN as an empty cell
                assert (math.isnan(row[cost]) and math.isnan(want[cost])) or float(row[cost]) == want[cost], (kind, i)
    assert any(s["searched"] for s in seen) and any(s["transitioned"] for s in seen)     # the checks saw both


def test_parquet_without_pyarrow_is_one_line(recorded, tmp_path, capsys):
    try:
        import pyarrow  # noqa: F401
        pytest.skip("pyarrow is installed")
    except ImportError:
        pass
    rc, _, err = cli(capsys, "trace", recorded["mm"][0], "--out", tmp_path / "t.parquet")
    assert rc == 1 and "pyarrow" in err and err.count("\n") == 1


@pytest.mark.parametrize("controller", ["mm", "lmm"])
def test_seeking_from_checkpoints_gives_the_recorded_poses(recorded, controller):
    """Ticks shown in a random order (back and forth, across resets, teleports and tuning changes) are
    re-simulated from controller-state checkpoints to the recorded poses bit for bit."""
    import numpy as np

    from app.commands.session_common import open_with_database
    from lmm.session.player import SessionPlayer
    from lmm.session.schema import pose_fingerprint
    from lmm.session.seek import SessionSeeker

    session, db, features, _ = open_with_database(recorded[controller][0])
    straight = SessionPlayer(session, db, features)
    poses = [pose_fingerprint(straight.step()[0][controller]) for _ in range(session.ticks)]
    seeker = SessionSeeker(session, db, features, every=60)
    rng = np.random.default_rng(3)
    ticks = [int(t) for t in rng.integers(0, session.ticks, 40)] + [session.ticks - 1, 0, 899, 300, 301, 150]
    for tick in ticks:
        got = pose_fingerprint(seeker.seek(tick)[0][controller])
        assert got == poses[tick], tick
        if (tick, controller) in session.fingerprints:
            assert got == session.fingerprints[(tick, controller)]
    assert seeker.stepped < len(ticks) * 60 + session.ticks     # never from the start again
    assert sorted(seeker.checkpoints) == list(range(0, session.ticks + 1, 60))[: len(seeker.checkpoints)]
    session.close()


def test_why_not_a_frame_adds_up_to_the_searchs_own_costs(recorded):
    """explain_frame on the controller just before a searching tick: the ranked candidates' totals and
    channel costs are the search's own, the continuing pose has no transition cost, and a frame next to the
    playing one is excluded by the window rule."""
    import numpy as np

    from app.commands.session_common import open_with_database
    from lmm.session.seek import SessionSeeker
    from lmm.session.why_not import explain_frame

    session, db, features, _ = open_with_database(recorded["mm"][0])
    seeker = SessionSeeker(session, db, features, every=60)
    checked = 0
    for tick in range(101, 700, 37):
        _, snaps = seeker.seek(tick)
        snap = snaps["mm"]
        if not snap.searched:
            continue
        seeker.seek(tick - 1)                        # the controller as the search found it
        mm, cands = seeker.controllers["mm"], snap.candidates
        for i, frame in enumerate(cands.frames.tolist()):
            why = explain_frame(mm, snap.query, frame)
            assert why["excluded"] == "", why
            assert why["total"] == pytest.approx(float(cands.costs[i]), rel=1e-5, abs=1e-6), (tick, frame)
            assert [why["channels"][n] for n in cands.channel_names] == pytest.approx(
                cands.channel_costs[i].tolist(), rel=1e-5, abs=1e-6)
            assert why["continuing"] == (frame == mm.frame) and (why["transition_cost"] == 0.0) == why["continuing"]
        near = explain_frame(mm, snap.query, mm.frame + 1)
        assert "exclude_current_window_frames" in near["excluded"] and np.isnan(near["total"])
        checked += 1
    assert checked >= 3
    assert "outside" in explain_frame(seeker.controllers["mm"], snap.query, db.n_frames)["excluded"]
    session.close()


def test_what_if_reranks_a_tick_as_a_fresh_search_with_that_tuning(recorded):
    """what_if with a scratch tuning (tag bias, transition cost, exclusion window) on the controller as a
    search found it gives the candidates that stepping that tick again with the scratch tuning gives."""
    from app.commands.session_common import open_with_database
    from lmm.session.seek import SessionSeeker
    from lmm.session.why_not import what_if

    session, db, features, _ = open_with_database(recorded["mm"][0])
    seeker = SessionSeeker(session, db, features, every=60)
    compared = changed = 0
    for tick in range(101, 700, 41):
        _, snaps = seeker.seek(tick)
        if not snaps["mm"].searched:
            continue
        query = snaps["mm"].query
        seeker.seek(tick - 1)
        mm = seeker.controllers["mm"]
        scratch = seeker.tuning.copy()
        scratch.set("transition_cost", 0.0)
        scratch.set("exclude_current_window_frames", 5)
        scratch.set("tag_bias", scratch.tag_bias["walk"] + 0.5, "walk")
        got = what_if(mm, query, scratch)
        assert mm.tuning is seeker.tuning
        changed += got.frames.tolist() != snaps["mm"].candidates.frames.tolist()
        for name, value in scratch.to_dict().items():          # the same tick stepped with the scratch tuning
            setattr(seeker.tuning, name, value)
        _, fresh = seeker.step()
        cands = fresh["mm"].candidates
        assert fresh["mm"].searched and got.frames.tolist() == cands.frames.tolist(), tick
        assert got.costs.tolist() == cands.costs.tolist()
        seeker.go_before(0)                                     # back to a checkpoint: the recorded tuning
        compared += 1
    assert compared >= 3 and changed >= 1                  # the scratch tuning did re-rank
    session.close()
