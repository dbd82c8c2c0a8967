"""Data checks: a planted T-pose and a raised range are found, exactly, and nothing else changes;
manifest tags; bad input gives one line naming the file."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from lmm import DEFAULT_MANIFEST
from lmm.data import bvh
from lmm.checks import check_manifest, check_take, motion_report, runs
from lmm.data.manifest import ManifestError, load_manifest

TAKE = DEFAULT_MANIFEST.parent / "lafan1" / "multipleActions1_subject3.bvh.gz"
BASE = (300, 1800)      # 50 s of the take, after its own calibration pose
TPOSE_FRAMES = 60       # 2 s at 30 fps
RAISED = (900, 960)     # in the base's frames: 2 s raised 50 cm


def _root_columns(anim):
    cols = anim.channel_columns(0)
    return {c.lower(): col for c, col in zip(anim.channels[0], cols)}


@pytest.fixture(scope="module")
def takes(tmp_path_factory):
    """(unmodified base copy, copy with a T-pose prepended and a range raised)."""
    folder = tmp_path_factory.mktemp("checks")
    anim = bvh.load(TAKE)
    base = anim.slice(*BASE)
    root = _root_columns(anim)
    # the calibration pose of the original take (frame 10), standing where the base starts
    tpose = np.repeat(anim.motion[10:11], TPOSE_FRAMES, axis=0)
    tpose[:, root["xposition"]] = base.motion[0, root["xposition"]]
    tpose[:, root["zposition"]] = base.motion[0, root["zposition"]]
    raised = base.motion.copy()
    raised[RAISED[0]:RAISED[1], root["yposition"]] += 50.0  # centimetres
    modified = base.slice(0, None)
    modified.motion = np.concatenate([tpose, raised])
    a, b = folder / "base.bvh.gz", folder / "planted.bvh.gz"
    bvh.save(a, base)
    bvh.save(b, modified)
    return a, b


def _near(f, kind, start, end, tol=15):
    return f.kind == kind and abs(f.start_frame - start) <= tol and abs(f.end_frame - end) <= tol


def test_planted_tpose_and_raised_range_are_found_and_nothing_else(takes):
    base_path, planted_path = takes
    base, _ = check_take(base_path, "base")
    planted, _ = check_take(planted_path, "planted")
    expected = [("calibration_pose", 0, TPOSE_FRAMES),
                ("airborne", RAISED[0] + TPOSE_FRAMES, RAISED[1] + TPOSE_FRAMES)]
    for kind, start, end in expected:
        hits = [f for f in planted if _near(f, kind, start, end)]
        assert len(hits) == 1, (kind, [f.line() for f in planted])
    rest = [f for f in planted if not any(_near(f, *e) for e in expected)]
    # everything else is a finding of the unmodified copy, moved by the prepended frames
    shifted = [(f.kind, f.start_frame + TPOSE_FRAMES, f.end_frame + TPOSE_FRAMES) for f in base]
    assert len(rest) == len(shifted), ([f.line() for f in rest], shifted)
    for f in rest:
        assert any(_near(f, *s, tol=2) for s in shifted), f.line()


def test_a_shipped_take_starts_with_its_calibration_pose():
    findings, _ = check_take(TAKE, "take")
    first = [f for f in findings if f.kind == "calibration_pose"][0]
    assert first.start_frame == 0 and 30 <= first.end_frame <= 120


def test_runs_merge_and_minimum_length():
    m = np.array([0, 1, 1, 0, 1, 1, 1, 0, 0, 0, 1], dtype=bool)
    assert runs(m) == [(1, 3), (4, 7), (10, 11)]
    assert runs(m, min_len=3) == [(4, 7)]
    assert runs(m, merge_gap=2) == [(1, 7), (10, 11)]
    assert runs(np.zeros(0, dtype=bool)) == []


def test_motion_report_counts_airborne_and_tpose_frames():
    names = ["Hips", "LeftToe", "RightToe", "LeftHand", "RightHand", "LeftArm", "RightArm"]
    F = 60
    g = np.zeros((F, len(names), 3))
    g[:, 0, 1] = 1.0
    g[:, 1, 0], g[:, 2, 0] = -0.1, 0.1
    g[:, 3:, 1] = 1.4
    g[:, 3, 0], g[:, 4, 0] = -0.3, 0.3          # hands close together: no T-pose ...
    g[:, 5, 0], g[:, 6, 0] = -0.2, 0.2
    g[40:, 3, 0], g[40:, 4, 0] = -0.8, 0.8       # ... until frame 40
    g[10:28, 1:3, 1] = 0.3                       # both toes up for 18 frames (0.3 s)
    r = motion_report(g, names, 60.0)
    assert r["airborne_frames"] == 18 and r["airborne_longest_s"] == pytest.approx(0.3)
    assert r["tpose_frames"] == 20


def _write_manifest(tmp_path, clips, name="m.json"):
    p = tmp_path / name
    p.write_text(json.dumps({"name": "t", "clips": clips}))
    return p


def test_manifest_tags_per_range_and_clip(tmp_path):
    p = _write_manifest(tmp_path, [{"file": str(TAKE), "tags": ["s3"],
                                    "ranges": [[100, 200], {"range": [300, 400], "tags": ["walk", "turn"]}]}])
    m = load_manifest(p)
    assert m.clips[0].range_tags == [("s3",), ("s3", "walk", "turn")]
    assert m.tag_names() == ["s3", "turn", "walk"]
    assert m.clips[0].source == str(TAKE)
    findings, cov = check_manifest(m)
    assert cov.seconds_per_tag["walk"] == pytest.approx(100 / 30)
    assert cov.seconds_per_tag["s3"] == pytest.approx(200 / 30)
    assert cov.speed_turn.seconds.sum() == pytest.approx(200 / 30)
    assert all(f.file == str(TAKE) for f in findings)


@pytest.mark.parametrize("clip, field", [
    ({"ranges": [{"range": [0, 10], "tags": ["Walk"]}]}, "clips[0].ranges[0].tags[0]"),
    ({"tags": "walk", "ranges": [[0, 10]]}, "clips[0].tags"),
    ({"ranges": [{"range": [0, 10], "tag": ["walk"]}]}, "clips[0].ranges[0].tag"),
    ({"ranges": [{"tags": ["walk"]}]}, "clips[0].ranges[0]"),
])
def test_bad_tags_name_the_manifest_clip_and_field(tmp_path, clip, field):
    p = _write_manifest(tmp_path, [{"file": str(TAKE), **clip}])
    with pytest.raises(ManifestError) as e:
        load_manifest(p)
    assert e.value.field == field and str(p.name) in str(e.value)


def test_check_data_cli_bad_input_is_one_line(tmp_path, capsys):
    from app.cli import main

    missing = _write_manifest(tmp_path, [{"file": "nowhere.bvh"}], "missing.json")
    broken = tmp_path / "broken.json"
    broken.write_text("{ not json")
    garbage = tmp_path / "garbage.bvh"
    garbage.write_text("HIERARCHY\nROOT Hips\n{\n")
    bad_take = _write_manifest(tmp_path, [{"file": str(garbage)}], "garbage.json")
    for manifest, named in ((missing, "nowhere.bvh"), (broken, "broken.json"), (bad_take, "garbage.bvh")):
        assert main(["check-data", "--manifest", str(manifest)]) == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith("lmm-studio check-data: error: ") and "\n" not in err and named in err, err


def test_check_data_cli_writes_json_and_png(tmp_path, capsys):
    from app.cli import main

    p = _write_manifest(tmp_path, [{"file": str(TAKE), "ranges": [{"range": [60, 1000], "tags": ["walk"]}]}])
    out_json, out_png = tmp_path / "c.json", tmp_path / "c.png"
    assert main(["check-data", "--manifest", str(p), "--json", str(out_json), "--png", str(out_png)]) == 0
    data = json.loads(out_json.read_text())
    assert {"file", "kind", "start_frame", "end_frame", "detail", "in_used_range"} <= set(data["findings"][0])
    assert data["coverage"]["seconds_per_tag"]["walk"] == pytest.approx(940 / 30, abs=0.01)
    from PIL import Image
    assert Image.open(out_png).size[0] > 100
    assert "walk" in capsys.readouterr().out


def test_raised_leg_while_slow_and_raised_arm_while_running_are_found():
    """A toe 40 cm up while standing is a raised leg; the same toe height in a running stride is not; a hand
    above the head while running is a raised arm (made-up joint paths at 30 fps)."""
    from lmm.checks import find_issues, take_signals
    names = ["Hips", "LeftToe", "RightToe", "LeftHand", "RightHand", "LeftArm", "RightArm", "Head"]
    fps, F = 30.0, 240
    g = np.zeros((F, len(names), 3))
    g[:, 0, 1], g[:, 1:3, 1], g[:, 3:5, 1], g[:, 5:7, 1], g[:, 7, 1] = 1.0, 0.05, 1.0, 1.4, 1.6
    g[:, 1, 2], g[:, 2, 2], g[:, 3, 2], g[:, 4, 2], g[:, 5, 2], g[:, 6, 2] = -.1, .1, -.3, .3, -.2, .2
    g[30:45, 1, 1] = 0.45                                   # standing: the left toe up for 0.5 s
    run = slice(120, 240)                                   # then running at 3 m/s
    g[run, :, 0] += (np.arange(120) * 3.0 / fps)[:, None]
    g[run, :, 0] -= g[120, 0, 0]
    g[150:165, 2, 1] = 0.40                                 # a high stride while running: not a raised leg
    g[190:200, 4, 1] = 1.9                                  # the right hand above the head while running
    g[120:, :, 0] += 10.0                                   # (a jump of place between the parts: never looked at)
    found = find_issues(take_signals(g, None, names, fps), "made-up")
    legs = [f for f in found if f.kind == "raised_leg"]
    arms = [f for f in found if f.kind == "raised_arm"]
    assert [(f.start_frame, f.end_frame) for f in legs] == [(30, 45)], [f.line() for f in found]
    assert len(arms) == 1 and abs(arms[0].start_frame - 190) <= 1 and abs(arms[0].end_frame - 200) <= 1
