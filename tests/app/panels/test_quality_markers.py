"""The studio's live motion quality (issue 34): the Stats panel's quality row and the timeline's markers of
transitions and flagged moments, in the real studio under Xvfb. With the leg IK's limits off (a hard reach,
no knee limiter: the runtime of before) a run of builtin:turns has knee snaps, and the timeline marks them."""
import json

import pytest


@pytest.mark.parametrize("limits", [False, True])
def test_quality_row_and_timeline_markers(run_studio, tmp_path, limits):
    preset = tmp_path / "preset.json"
    fields = {} if limits else {"ik_min_knee_deg": 0.0, "ik_soft_reach_m": 0.0, "ik_knee_max_acceleration_deg_s2": 0.0}
    preset.write_text(json.dumps(fields))
    r = run_studio("--frames", 480, "--fixed-step", "--input", "builtin:turns", "--tuning", preset,
                   "--no-save-layout", script=[{"frame": 479, "do": "capture", "label": "end"}], timeout=400)
    assert r.rc == 0, r
    p = r.dump["labels"]["end"]["panels"]
    assert "MM quality:" in p["stats"]["quality"] and "knee snaps/min" in p["stats"]["quality"]
    assert "slow accel p99" in p["stats"]["quality"] and "frames played" in p["stats"]["quality"]
    markers = p["timeline"]["markers"]
    assert markers["trans"]["mm"] > 5                      # MM's transitions over 8 s of turns
    if limits:
        assert "0.0 knee snaps/min" in p["stats"]["quality"].splitlines()[0]
    else:
        assert markers["flags"]["mm"] > 0                  # the snaps the hard reach makes are marked
