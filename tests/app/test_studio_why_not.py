"""Why not and what if in the studio (issue 33 item 4), in one studio run under Xvfb: a headless ``run
--session`` reopened with ``--open``; at a searching tick the Search Candidates panel explains an excluded
and a ranked frame as :func:`lmm.session.why_not.explain_frame` does, and shows the tick's search re-ranked
under a scratch tuning as :func:`lmm.session.why_not.what_if` does, marked *what if*."""
from __future__ import annotations

import json

import numpy as np
import pytest

from studio_testutil import run_reopened

pytestmark = pytest.mark.gui

LATER = 60          # B is compared with A this many ticks after the branch


def _expected(session_path):
    """A searching history tick of the session, its explanations of an excluded and a ranked frame, and its
    what-if frames under ``transition_cost = 0``: computed headless."""
    from app.commands.session_common import open_with_database
    from app.why_not_probe import chosen_frame, explanation_lines
    from lmm.session.player import SessionPlayer
    from lmm.session.seek import SessionSeeker
    from lmm.session.why_not import explain_frame, what_if

    session, db, features, _ = open_with_database(session_path)
    seeker = SessionSeeker(session, db, features)
    for step in range(150, 290):
        snap = seeker.seek(step)[1]["mm"]
        ranked = [f for f in snap.candidates.frames.tolist() if f != snap.matched_frame] if snap.searched else []
        if ranked:
            break
    with seeker.before(step) as controllers:
        mm = controllers["mm"]
        near = int(mm.frame) + 1
        whys = {}
        for frame in (near, ranked[-1]):
            whys[frame] = {"tick": step + 1, "controller": "mm", "note": "",
                           "asked": explain_frame(mm, snap.query, frame),
                           "chosen": explain_frame(mm, snap.query, chosen_frame(snap)),
                           "continuing": explain_frame(mm, snap.query, int(mm.frame))}
        scratch = seeker.tuning.copy()
        scratch.set("feature_weights", 4.0, "hip_velocity")
        rerank = what_if(mm, snap.query, scratch).frames.tolist()
        branch = scratch.to_dict()
    assert rerank != snap.candidates.frames.tolist()           # the scratch weight does re-rank
    lines = {f: "\n".join(explanation_lines(w, features.names)) for f, w in whys.items()}
    # Branch here with that scratch tuning: ab's arm B against arm A, LATER ticks on
    arms = [SessionPlayer(session, db, features), SessionPlayer(session, db, features, branch=branch, from_tick=step)]
    for _ in range(step + 1 + LATER):                          # history tick n: the pose after n steps
        poses = [arm.step()[0]["mm"].global_positions.astype(np.float64) for arm in arms]
    difference = np.linalg.norm(poses[0] - poses[1], axis=-1)
    session.close()
    return step + 1, near, ranked[-1], whys, lines, rerank, difference


def test_why_not_and_what_if_in_a_reopened_session(xvfb_display, studio_cache, tmp_path):
    from app.cli import main as cli_main

    session = tmp_path / "s.lmmsession"
    events = tmp_path / "events.json"           # one slider move before the asked tick: the Tuning panel shows it
    events.write_text(json.dumps({"events": [{"tick": 100, "kind": "tuning",
                                              "payload": {"field": "transition_cost", "new": 0.25}}]}))
    assert cli_main(["run", "--controller", "mm", "--input", "builtin:random:1", "--seconds", "5",
                     "--events", str(events), "--session", str(session), "--quiet"]) == 0
    tick, excluded, ranked, whys, lines, rerank, difference = _expected(session)
    assert "exclude_current_window_frames" in whys[excluded]["asked"]["excluded"]
    assert whys[ranked]["asked"]["excluded"] == "" and whys[ranked]["asked"]["total"] > 0
    script = [{"frame": 4, "do": "scrub", "tick": tick},
              {"frame": 6, "do": "why_not", "database_frame": excluded}, {"frame": 8, "do": "capture", "label": "excluded"},
              {"frame": 9, "do": "database", "op": "frame", "db_frame": ranked},      # the Database panel's button
              {"frame": 10, "do": "database", "op": "why_not"}, {"frame": 12, "do": "capture", "label": "ranked"},
              {"frame": 14, "do": "what_if", "field": "feature_weights", "channel": "hip_velocity", "value": 4.0},
              {"frame": 16, "do": "capture", "label": "what_if"},
              {"frame": 17, "do": "branch_here", "scratch": True},
              {"frame": 18, "do": "what_if", "clear": True}, {"frame": 20, "do": "capture", "label": "cleared"},
              {"frame": 22, "do": "scrub", "tick": tick + LATER}, {"frame": 25, "do": "capture", "label": "branch"},
              {"frame": 27, "do": "scrub", "tick": tick - 20}, {"frame": 30, "do": "capture", "label": "before"},
              {"frame": 32, "do": "scrub", "tick": 50}, {"frame": 35, "do": "capture", "label": "early"},
              {"frame": 37, "do": "live"}, {"frame": 40, "do": "capture", "label": "live"},
              {"frame": 41, "do": "why_not", "database_frame": 5}, {"frame": 43, "do": "capture", "label": "live_ask"}]
    data = run_reopened(session, tmp_path, xvfb_display, studio_cache, script, frames=45)
    assert not data["errors"], data["errors"]
    labels = data["labels"]
    for label, frame in (("excluded", excluded), ("ranked", ranked)):
        cands = labels[label]["panels"]["candidates"]
        assert labels[label]["displayed_tick"] == tick
        assert cands["why_not"] == lines[frame], label
    tuning = {label: labels[label]["panels"]["tuning"] for label in ("ranked", "early")}
    assert tuning["ranked"]["values"]["tun_transition_cost"] == pytest.approx(0.25)
    assert tuning["early"]["values"]["tun_transition_cost"] != pytest.approx(0.25)       # before the move
    assert tuning["ranked"]["note"].startswith("the session's tuning at the picked tick (read-only")
    cont = whys[ranked]["continuing"]                          # the continuing pose's own row
    assert (f"continuing pose {cont['frame']}: total {cont['total']:.3f} = features {cont['feature_cost']:.3f}"
            in labels["ranked"]["panels"]["candidates"]["status"])
    assert "excluded: within" in labels["excluded"]["panels"]["candidates"]["why_not"]
    assert f"total {whys[ranked]['asked']['total']:.3f}" in labels["ranked"]["panels"]["candidates"]["why_not"]
    shown = labels["what_if"]["panels"]["candidates"]
    assert shown["what_if"]["tick"] == tick
    assert [r["frame"] for r in shown["rows"]] == rerank          # sorted by total: the re-ranked order
    assert "WHAT IF (scratch tuning: feature_weights.hip_velocity=4.0)" in shown["status"]
    assert "WHAT IF" not in labels["cleared"]["panels"]["candidates"]["status"]
    assert labels["cleared"]["panels"]["candidates"]["what_if"] is None
    assert f"SESSION   |   tick {tick}" in labels["ranked"]["panels"]["menu"]["status"]
    # Branch here with the scratch tuning: B beside A (a ghost) and the difference row ab's arms give
    row = labels["branch"]["panels"]["stats"]["branch"]
    assert row.startswith(f"A vs B (from tick {tick}), tick {tick + LATER}: pose difference mean "
                          f"{difference.mean():.3f} m, max {difference.max():.3f} m"), row
    assert difference.max() > 0
    ghosts = [g["label"] for g in labels["branch"]["panels"]["viewport"]["previews"]]
    assert f"B (from tick {tick})" in ghosts, ghosts
    assert labels["before"]["panels"]["stats"]["branch"] == f"branch B from tick {tick}: before it, B is A"
    # live again: the session's answers are dropped, and a live tick cannot be asked (one line says why)
    assert labels["live"]["panels"]["candidates"]["why_not"] == "" and "LIVE" in labels["live"]["panels"]["menu"]["status"]
    assert labels["live"]["panels"]["stats"]["branch"] == ""
    assert labels["live_ask"]["panels"]["candidates"]["why_not"].startswith("why not / what if ask a reopened session")
