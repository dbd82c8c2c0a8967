"""Follow a reference in the studio: a reference BVH drives both characters, it is drawn with them, each
controller's pose error against it is plotted, and scrubbing shows the aligned frame of the picked tick."""
import numpy as np

from lmm.data import bvh
from studio_testutil import ROOT

TAKE = ROOT / "lmm" / "data" / "lafan1" / "obstacles3_subject3.bvh.gz"


def _write_range(path, rename=None):
    anim = bvh.load(TAKE).slice(3526, 3781)       # a held-out walk, 8.5 s
    if rename:
        anim = bvh.Animation.from_local([rename.get(n, n) for n in anim.names], anim.parents, anim.offsets,
                                        anim.local_rotations(), anim.local_positions(), anim.frame_time)
    bvh.save(path, anim)
    return path


def test_follow_a_reference_and_see_the_error_plotted(run_studio, tmp_path, lmm_weights):
    walk = _write_range(tmp_path / "walk.bvh")
    pelvis = _write_range(tmp_path / "pelvis.bvh", {"Hips": "Pelvis"})
    script = [{"frame": 2, "do": "open", "kind": "reference", "path": str(pelvis)},
              {"frame": 3, "do": "follow", "on": True},                      # no Hips: cannot follow
              {"frame": 5, "do": "capture", "label": "refused"},
              {"frame": 6, "do": "dismiss"},
              {"frame": 8, "do": "open", "kind": "reference", "path": str(walk)},
              {"frame": 10, "do": "follow", "on": True},
              {"frame": 190, "do": "capture", "label": "live"},
              {"frame": 191, "do": "scrub", "back": 90},
              {"frame": 194, "do": "capture", "label": "scrubbed"},
              {"frame": 195, "do": "follow", "on": True, "overlay": True},
              {"frame": 200, "do": "capture", "label": "overlay"}]
    args = ["--frames", 201] + (["--weights", lmm_weights] if lmm_weights else ["--no-lmm"])
    r = run_studio(*args, script=script)
    assert r.rc == 0, r.stderr[-3000:]
    d = r.dump
    names = ["mm", "lmm"] if lmm_weights else ["mm"]
    assert d["controllers"] == names

    # the skeleton without the manifest's hips: one line in the error dialog, still drawn (by time)
    assert len(d["errors"]) == 1, d["errors"]
    msg = d["errors"][0]["message"]
    assert "pelvis.bvh" in msg and "Hips" in msg and "\n" not in msg
    refused = d["labels"]["refused"]["panels"]
    assert refused["recording"]["follow"]["following"] == "" and refused["viewport"]["reference"]["frame"] == -1

    # following: the input is the reference's, every controller's error is plotted, finite and plausible
    live = d["labels"]["live"]
    follow = live["panels"]["recording"]["follow"]
    assert follow["following"] == "walk.bvh" and live["panels"]["recording"]["input"] == "reference walk.bvh"
    tick = live["displayed_tick"]
    assert 150 < tick <= 190
    for n in names:
        p = follow["plotted"][n]
        assert p["points"] == tick and p["finite"] == tick, p                 # one point per tick since the reset
        assert 0.05 < p["mean"] < 1.0 and p["max"] < 1.5, p
        now = follow["now"][n]
        assert 0.05 < now["error_rad"] < 1.0
        assert abs(now["frame"] - tick / 60 * 30) <= 9.5                       # within 0.3 s of the tick's time
    assert follow["cursor_s"] == follow["cursor_plotted"] == 0.0
    # the characters follow the reference's root
    ref = live["panels"]["viewport"]["reference"]
    for n in names:
        root = np.asarray(live["snapshot_roots"][n])
        assert np.linalg.norm((root - np.asarray(ref["root_path"]))[[0, 2]]) < 0.3, (n, root, ref)
    assert np.linalg.norm(np.asarray(ref["root_path"])[[0, 2]]) > 2.0           # ... which has walked on
    # the reference is drawn at the inspected controller's aligned frame, to the left
    assert ref["frame"] == follow["now"]["mm"]["frame"] and ref["offset"] == [-1.6, 0.0, 0.0]

    # scrubbing: the reference at the aligned frame of the picked tick, the cursor at that tick
    scr = d["labels"]["scrubbed"]
    follow_s = scr["panels"]["recording"]["follow"]
    assert scr["displayed_tick"] < tick - 60
    assert abs(follow_s["cursor_plotted"] - (scr["displayed_tick"] - follow_s["plotted"]["mm"]["points"]) / 60) < 0.05
    assert scr["panels"]["viewport"]["reference"]["frame"] == follow_s["now"]["mm"]["frame"] < ref["frame"]

    # overlay: drawn over the inspected (MM) character, with a fresh start (follow again resets)
    over = d["labels"]["overlay"]
    assert over["panels"]["viewport"]["reference"]["offset"] == [0.0, 0.0, 0.0]
    assert over["displayed_tick"] <= 6
