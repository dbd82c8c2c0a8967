"""The Database panel and the 3D view's preview ghosts: the data they are made of (no display), then
the real studio under Xvfb driven by a script (the data layout, previews, playback, candidate clicks,
copying a manifest range, bad selections reported in one line while the studio keeps running)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from app import layout_files as layouts
from app.panels.database import database_preview, range_rows, take_name
from app.panels.viewport_previews import PREVIEW_SPACING_M, place, preview_placement
from lmm import DEFAULT_MANIFEST, quat
from lmm.data.manifest import load_manifest
from lmm.data.ranges import database_ranges


@pytest.fixture(scope="module")
def dbf():
    from lmm.data.build import load_or_build
    from lmm.features import build_features

    db, _ = load_or_build()
    return db, build_features(db)


def test_preview_pose_is_the_frame_in_its_simulation_bone_frame(dbf):
    db, features = dbf
    frame = 4321
    pose = database_preview(db, features, frame, "x")
    rot, pos = db.global_transforms(slice(frame, frame + 1))
    # back in the world with the frame's own simulation bone: the database's global pose
    world = place(pose.positions, pos[0, 0], quat.to_matrix(rot[0, 0]))
    assert np.allclose(world, pos[0], atol=1e-5)
    assert np.allclose(pose.positions[0], 0.0, atol=1e-6)
    assert list(pose.parents) == list(db.parents) and pose.names == tuple(db.names)
    # the future trajectory: the database's own root positions 20/40/60 frames ahead, in that frame
    ahead = db.future_frame(frame, np.array([20, 40, 60]))
    _, future = db.global_transforms(ahead)
    expect = quat.inv_mul_vec(rot[0, 0][None], future[:, 0] - pos[0, 0][None])
    assert np.allclose(pose.trajectory[:, [0, 2]], expect[:, [0, 2]], atol=1e-3)
    assert len(pose.directions) == 3 and len(pose.points) >= 2
    # another frame is another pose
    other = database_preview(db, features, frame + 30, "y")
    assert not np.allclose(other.positions, pose.positions, atol=1e-3)


def test_preview_ghosts_stand_beside_the_character_facing_its_way():
    anchor = np.array([3.0, 0.0, -2.0])
    turn = quat.from_axis_angle(np.array([0.0, 1.0, 0.0]), np.array(np.pi / 2))
    origin, rot = preview_placement(anchor, turn, 0)
    assert np.allclose(origin, anchor + [-PREVIEW_SPACING_M, 0.0, 0.0])
    assert np.allclose(place([[0.0, 0.0, 1.0]], origin, rot)[0] - origin, [1.0, 0.0, 0.0], atol=1e-9)
    origin2, _ = preview_placement(anchor, turn, 1)
    assert np.allclose(origin2, anchor + [-2 * PREVIEW_SPACING_M, 0.0, 0.0])


def test_range_rows_name_takes_shortly(dbf):
    db, _ = dbf
    rows = range_rows(database_ranges(db, load_manifest(DEFAULT_MANIFEST)))
    assert len(rows) == db.n_ranges
    assert rows[0]["take"] == "multiActions1 s1" and rows[0]["frames"] == "545:645"
    assert rows[1]["mirrored"] and not rows[0]["mirrored"]
    assert take_name("lafan1/walk1_subject5.bvh.gz") == "walk1 s5"


def test_the_data_layout_places_the_workbench():
    lay = layouts.load("data")
    shown = {k for k in lay.windows if k not in lay.hidden}
    assert {"viewport", "database", "coverage", "motion_search", "timeline"} <= shown
    for name in ("default", "compare", "tuning"):
        assert {"database", "coverage", "motion_search"} <= layouts.load(name).hidden


# -----------------------------------------------------------------------------------------------
# the real studio
# -----------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def data_run(xvfb_display, studio_cache, tmp_path_factory):
    """The data layout with MM only: a range is played, a small looped selection, a candidate clicked,
    the timeline scrubbed while a preview shows, a manifest range copied and bad selections tried."""
    import os
    import subprocess
    import sys

    from studio_testutil import ROOT

    tmp = tmp_path_factory.mktemp("database")
    shot = tmp / "data.png"
    script = [
        {"frame": 2, "do": "layout", "name": "data"},
        {"frame": 10, "do": "database", "op": "copy"},
        {"frame": 12, "do": "dismiss"},
        {"frame": 30, "do": "database", "op": "select", "range": 4},
        {"frame": 31, "do": "capture", "label": "selected"},
        {"frame": 32, "do": "database", "op": "play"},
        {"frame": 52, "do": "capture", "label": "played"},
        {"frame": 53, "do": "database", "op": "selection", "start": 2040, "stop": 2044},
        {"frame": 54, "do": "database", "op": "scrub", "source_frame": 2040},
        {"frame": 64, "do": "capture", "label": "looped"},
        {"frame": 65, "do": "database", "op": "copy"},
        {"frame": 66, "do": "capture", "label": "copied"},
        {"frame": 70, "do": "database", "op": "pause"},
        {"frame": 76, "do": "show", "window": "candidates"},
        {"frame": 80, "do": "pause"},
        {"frame": 82, "do": "click_candidate", "row": 2},
        {"frame": 84, "do": "capture", "label": "candidate"},
        {"frame": 85, "do": "screenshot", "path": str(shot)},
        {"frame": 86, "do": "scrub", "back": 60},
        {"frame": 88, "do": "capture", "label": "scrubbed"},
        {"frame": 89, "do": "database", "op": "select", "range": 4},
        {"frame": 90, "do": "database", "op": "selection", "start": 3000, "stop": 3300},
        {"frame": 91, "do": "database", "op": "selection", "start": 2500, "stop": 2500},
        {"frame": 92, "do": "database", "op": "select", "range": 999},
        {"frame": 93, "do": "database", "op": "frame", "db_frame": 10 ** 7},
        {"frame": 95, "do": "live"},
        {"frame": 118, "do": "capture", "label": "end"},
    ]
    (tmp / "script.json").write_text(json.dumps({"actions": script}))
    env = dict(os.environ, DISPLAY=xvfb_display, LMM_STUDIO_CONFIG=str(tmp / "config"),
               LMM_STUDIO_CACHE=str(studio_cache), PYTHONPATH=str(ROOT), LP_NUM_THREADS="0")
    proc = subprocess.run([sys.executable, "-m", "app.cli", "--frames", "120", "--input", "builtin:circle",
                           "--no-lmm", "--no-gamepads", "--script", str(tmp / "script.json"),
                           "--dump-state", str(tmp / "dump.json")],
                          cwd=tmp, env=env, capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return {"dump": json.loads((tmp / "dump.json").read_text()), "shot": shot}


def labels(run):
    return run["dump"]["labels"]


@pytest.mark.gui
def test_the_data_layout_shows_the_database_panel(data_run):
    d = data_run["dump"]
    assert d["layout"] == "data" and d["frames_run"] == 120
    windows = d["final"]["windows"]
    assert windows["database"]["shown"] and windows["viewport"]["shown"] and windows["timeline"]["shown"]
    assert not windows["tuning"]["shown"]


@pytest.mark.gui
def test_selecting_a_range_previews_its_first_frame_beside_the_character(data_run):
    from lmm.data.build import load_or_build

    db, _ = load_or_build()
    sel = labels(data_run)["selected"]
    p = sel["panels"]["database"]
    assert p["selected"] == 4 and p["frame"] == int(db.range_starts[4]) and p["source_frame"] == 2007
    assert p["file"] == "lafan1/multipleActions1_subject1.bvh.gz" and p["rows"] == db.n_ranges
    ghosts = sel["panels"]["viewport"]["previews"]
    assert len(ghosts) == 1 and ghosts[0]["label"].startswith("preview: multipleActions1_subject1")
    # beside the displayed character (its simulation bone), on the ground
    root = np.array(sel["snapshot_roots"]["mm"])
    assert np.linalg.norm(np.array(ghosts[0]["origin"])[[0, 2]] - (root[[0, 2]] - [1.3, 0.0])) < 0.6
    assert ghosts[0]["head"][1] > 1.2                        # a standing person, not a collapsed one


@pytest.mark.gui
def test_playing_advances_one_frame_per_studio_frame_and_loops_the_selection(data_run):
    lab = labels(data_run)
    a, b = lab["selected"], lab["played"]
    played = b["panels"]["database"]["frame"] - a["panels"]["database"]["frame"]
    assert played == b["frame"] - a["frame"] - 1      # play asked at the frame after "selected", counted from the next
    assert b["panels"]["database"]["playing"]
    assert b["panels"]["viewport"]["previews"][0]["label"] != a["panels"]["viewport"]["previews"][0]["label"]
    looped = lab["looped"]["panels"]["database"]
    assert looped["selection"] == [2040, 2044]
    assert 2040 <= looped["source_frame"] <= 2043             # stays inside the looped selection


@pytest.mark.gui
def test_copy_gives_the_manifest_range_in_the_files_frames(data_run):
    copied = labels(data_run)["copied"]["panels"]["database"]["copied"]
    assert json.loads(copied) == {"range": [2040, 2044], "tags": ["walk", "strafe", "turn"]}


@pytest.mark.gui
def test_clicking_a_candidate_previews_its_frame_and_follows_the_scrubbed_tick(data_run):
    lab = labels(data_run)
    cand = lab["candidate"]["panels"]
    frame = cand["candidates"]["rows"][2]["frame"]
    assert cand["database"]["frame"] == frame and cand["database"]["origin"] == "candidate"
    assert not cand["database"]["playing"]
    assert cand["viewport"]["previews"][0]["label"].startswith("candidate: ")
    # scrubbing 1 s back: the ghost stands beside the character of the picked tick
    scrub = lab["scrubbed"]
    assert scrub["displayed_tick"] == lab["candidate"]["displayed_tick"] - 60
    assert scrub["panels"]["database"]["tick"] == scrub["displayed_tick"]
    root = np.array(scrub["snapshot_roots"]["mm"])
    origin = np.array(scrub["panels"]["viewport"]["previews"][0]["origin"])
    assert np.linalg.norm(origin[[0, 2]] - (root[[0, 2]] - [1.3, 0.0])) < 0.6
    before = np.array(cand["viewport"]["previews"][0]["origin"])
    assert np.linalg.norm(origin - before) > 0.3            # the character moved in that second


@pytest.mark.gui
def test_bad_selections_are_one_line_errors_and_the_studio_keeps_running(data_run):
    d = data_run["dump"]
    msgs = [e["message"] for e in d["errors"] if e["title"] == "Database"]
    assert len(msgs) == 5, msgs
    assert all("\n" not in m for m in msgs)
    nothing, past, empty, no_range, no_frame = msgs
    assert "select a range first" in nothing
    assert past.startswith("lafan1/multipleActions1_subject1.bvh.gz") and "past the end" in past
    assert empty.startswith("lafan1/multipleActions1_subject1.bvh.gz") and "empty" in empty
    assert "no database range 999" in no_range and "no database frame 10000000" in no_frame
    end = labels(data_run)["end"]
    assert end["displayed_tick"] > labels(data_run)["scrubbed"]["displayed_tick"]   # resumed, still running
    assert end["panels"]["database"]["frame"] >= 0


@pytest.mark.gui
def test_screenshot_of_the_data_layout(data_run):
    from PIL import Image

    img = np.asarray(Image.open(data_run["shot"]).convert("RGB"), dtype=np.float32)
    assert img.shape[:2] == (900, 1600)
    # the preview ghost's green is in the 3D view (the panel's green bars are left of x=430)
    view = img[60:540, 440:1170]
    green = (view[..., 1] > view[..., 0] + 40) & (view[..., 1] > view[..., 2] + 30)
    assert green.sum() > 300


def test_preview_hook_takes_any_skeleton_and_hides_unused_ghosts():
    """The hook other panels reuse (search results from other BVH skeletons): one skeleton per slot,
    made again when a pose with other parents arrives, hidden when fewer poses are shown."""
    from types import SimpleNamespace

    from app.panels.base import PreviewPose
    from app.panels.viewport_markers import MarkerBatch
    from app.panels.viewport_previews import PreviewDrawings

    made = []

    class FakeSkeleton:
        def __init__(self, ctx, parents, **kw):
            self.parents, self.visible, self.released, self.positions = list(parents), True, False, None
            made.append(self)

        def update(self, positions):
            self.positions = np.asarray(positions)

        def release(self):
            self.released = True

    class FakeRenderable:
        def __init__(self, *a, **k):
            self.args = None

        def update(self, *a, **k):
            self.args = a

    scene = SimpleNamespace(items=[])
    scene.add = lambda *r: scene.items.extend(r)
    scene.remove = lambda r: scene.items.remove(r)
    viewer = SimpleNamespace(Skeleton=FakeSkeleton, Spheres=FakeRenderable, Arrows=FakeRenderable,
                             Lines=FakeRenderable)
    batch = MarkerBatch(viewer, None)
    drawings = PreviewDrawings(viewer, None, scene)
    three = PreviewPose("a", np.array([[0, 0, 0], [0, 1, 0], [0, 2, 0.0]]), np.array([-1, 0, 1]),
                        trajectory=np.array([[0, 0, 1.0], [0, 0, 2.0]]))
    two = PreviewPose("b", np.array([[0, 0, 0], [0, 1.5, 0.0]]), np.array([-1, 0]))
    out = drawings.update([three, two], batch, np.array([2.0, 0, 0]), np.array([1.0, 0, 0, 0]), "capsules", True)
    assert [d["label"] for d in out] == ["a", "b"] and len(made) == 2 and len(scene.items) == 2
    assert np.allclose(made[0].positions[2], [2.0 - PREVIEW_SPACING_M, 2.0, 0.0])
    assert np.allclose(made[1].positions[0], [2.0 - 2 * PREVIEW_SPACING_M, 0.0, 0.0])
    # slot 0 gets the two-joint skeleton: made again; slot 1 unused: hidden
    out = drawings.update([two], batch, np.zeros(3), np.array([1.0, 0, 0, 0]), "capsules", True)
    assert len(made) == 3 and made[0].released and made[2].parents == [-1, 0]
    assert made[2].visible and not made[1].visible and len(scene.items) == 2


@pytest.mark.gui
def test_a_real_click_on_a_candidate_row_previews_its_frame_xdotool(xvfb_display, studio_cache, tmp_path):
    """Click the second row of Search Candidates with the mouse (xdotool): the Database window opens on
    that database frame and the 3D view shows it as a candidate ghost."""
    import shutil
    import time

    from studio_testutil import RealKeyStudio

    if shutil.which("xdotool") is None:
        pytest.skip("xdotool is not installed")
    rects = tmp_path / "rects.json"
    actions = [{"frame": 30, "do": "pause"},
               {"frame": 40, "do": "write_rects", "path": str(rects), "items": ["cand_1_rank"]}]
    with RealKeyStudio(tmp_path, xvfb_display, studio_cache, actions,
                       ["--layout", "default", "--input", "builtin:circle"]) as s:
        x0, y0, x1, y1 = s.rect(rects, "cand_1_rank", settle_s=1.0)
        s.xdo("windowfocus", "--sync", s.win)
        s.xdo("mousemove", "--window", s.win, str(int(x0 + 6)), str(int((y0 + y1) / 2)))
        s.xdo("click", "1")
        time.sleep(1.5)
    assert s.returncode == 0, s.stderr[-3000:]
    final = s.dump()["final"]
    frame = final["candidates"]["rows"][1]["frame"]
    assert final["database"]["frame"] == frame and final["database"]["origin"] == "candidate"
    assert final["windows"]["database"]["shown"]
    assert final["viewport"]["previews"][0]["label"].startswith("candidate: ")
