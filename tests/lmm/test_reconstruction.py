"""The reconstruction benchmark (lmm.reconstruction, ``lmm-studio eval --reconstruction``)."""
import json

import numpy as np
import pytest

from lmm import DEFAULT_MANIFEST
from lmm.data.manifest import load_manifest
from lmm.reconstruction import HELDOUT_FILE, HeldOut, format_table, load_heldout, run_take, summarize


def test_heldout_ranges_are_not_used_by_the_default_database():
    m = load_manifest(DEFAULT_MANIFEST)
    used = {c.file.name: c.ranges for c in m.clips}
    takes, _ = load_heldout(HELDOUT_FILE, shared_dir="/nonexistent")   # the shipped ones at least
    assert len(takes) >= 3 and {t.motion for t in takes} >= {"walk", "run"}
    for t in takes:
        a, b = t.frames
        for ua, ub in used.get(t.file.name, []):
            assert b <= ua or ub <= a, (t.name, t.frames, (ua, ub))


def test_a_held_out_range_through_mm(tmp_path):
    from lmm.data.build import load_or_build
    from lmm.factory import make_controller
    from lmm.features import build_features
    db, _ = load_or_build(None)
    features = build_features(db)
    m = load_manifest(DEFAULT_MANIFEST)
    takes, _ = load_heldout(HELDOUT_FILE, shared_dir="/nonexistent")
    walk = next(t for t in takes if t.motion == "walk")
    short = HeldOut(walk.file, walk.name, (walk.frames[0], walk.frames[0] + 120), walk.motion)
    r = run_take(short, db, features, m, {"mm": make_controller("mm", db, features)})
    c = r["controllers"]["mm"]
    assert abs(r["seconds"] - 4.0) < 0.05 and r["input_path_error"]["position_mean_m"] < 0.2
    # a controller's walk is not the take's walk, but it is a walk in the same place
    assert 0.02 < c["rotation_error_rad"] < 1.0 and c["root_path_error_cm"] < 30.0
    assert 0.0 < c["position_error_cm"]["root_relative"] < 40.0
    assert len(c["per_frame_rotation_error_rad"]) == 120 and np.isfinite(c["per_frame_rotation_error_rad"]).all()
    s = summarize([r], ["mm"])
    assert s["walk"]["mm"]["rotation_error_rad"] == pytest.approx(c["rotation_error_rad"])
    assert "| **all** (1 takes)" in format_table([r], s, ["mm"])


def test_a_broken_heldout_list_is_one_line(tmp_path):
    from lmm.errors import InputError
    bad = tmp_path / "h.json"
    bad.write_text(json.dumps({"takes": [{"file": "x.bvh"}]}))
    with pytest.raises(InputError, match=r"h\.json: takes\[0\]"):
        load_heldout(bad)
