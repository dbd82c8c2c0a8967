"""The studio's data shaping, without a display: what each panel computes from snapshots, the
layout files, the session (controllers, recording, replay) and the tuning widgets."""
import dataclasses
import os
from types import SimpleNamespace

import numpy as np
import pytest

from app.history import History, Tick
from app import layout_files as layouts
from app.frame_times import per_tick_ms
from app.panels.base import View
from app.panels.common import cost_color, decimate, fmt_bytes, overlapping, short_channel_name
from app.panels.menu import hidden_note
from app.panels.features import bar_layout, bar_values, channel_errors
from app.panels.latent import diverging_lut, heat_image, latent_scale
from app.panels.candidates import candidate_rows, column_fractions, sort_rows
from app.panels.search import frame_label, rolling_agreement
from app.frame_times import FrameTimes
from app.panels.timeline import scrub_target
from app.panels.tuning import pretty_label, widget_specs
from app.panels.viewport_labels import separate_labels
from app.panels.viewport_scene import feature_markers
from app.recording import RecordingResult, recording_paths
from app.reference_clip import load_reference_clip
from app.session import Session
from lmm.controller import Candidates, InputState
from lmm.factory import make_controllers
from lmm.tuning import Tuning, TuningError

from studio_testutil import CORPUS


@pytest.fixture(scope="module")
def dbf():
    from lmm.data.build import load_or_build
    from lmm.features import build_features

    db, _ = load_or_build()
    return db, build_features(db)


# -- feature bars ---------------------------------------------------------------------------------

def test_bar_layout_groups_dimensions_by_channel(dbf):
    _, features = dbf
    lay = bar_layout(features)
    assert len(lay["x"]) == features.n_dims == 27
    assert len(lay["labels"]) == len(lay["centres"]) == len(features.layout)
    assert len(lay["separators"]) == len(features.layout) - 1
    # a gap between channels, none inside one
    steps = np.diff(lay["x"])
    assert np.sum(steps > 1.5) == len(features.layout) - 1 and np.all(steps >= 1.0)
    assert "w 0.75" in lay["labels"][0] and "w 1.50" in lay["labels"][-1]
    for sep, (a, b) in zip(lay["separators"], zip(features.slices[:-1], features.slices[1:])):
        assert lay["x"][a.stop - 1] < sep < lay["x"][b.start]


def _view(snaps: dict, inspected="mm"):
    h = History(10)
    t = Tick(1, 1 / 60, snaps)
    return View(tick=t, history=h, live=True, paused=False, inspected=inspected)


def test_bar_values_take_query_matched_and_projected():
    q, m, p = np.arange(3.0), np.ones(3), np.full(3, 2.0)
    mm = SimpleNamespace(query=q, matched_features=m, projected_features=None)
    lmm = SimpleNamespace(query=q + 10, matched_features=m, projected_features=p)
    vals = bar_values(_view({"mm": mm, "lmm": lmm}))
    assert vals["query"].tolist() == q.tolist() and vals["matched"].tolist() == m.tolist()
    assert vals["projected"].tolist() == p.tolist()
    vals = bar_values(_view({"mm": mm, "lmm": lmm}, inspected="lmm"))
    assert vals["query"].tolist() == (q + 10).tolist()
    assert bar_values(_view({"mm": mm}))["projected"] is None


def test_channel_errors(dbf):
    _, features = dbf
    a = np.zeros(27)
    b = np.zeros(27)
    b[features.slices[1]] = 1.0
    err = channel_errors(features, a, b)
    assert err[1] == 3.0 and sum(err) == 3.0
    assert all(np.isnan(channel_errors(features, a, None)))


# -- latent heat maps -----------------------------------------------------------------------------

def test_heat_image_is_row_per_dimension_newest_right():
    lut = diverging_lut(256)
    assert lut.shape == (256, 4) and lut[0, 2] > lut[0, 0] and lut[-1, 0] > lut[-1, 2]   # blue .. red
    v = np.zeros((10, 3))
    v[-1, 0] = 1.0        # newest tick, dimension 0: full positive
    v[0, 2] = -1.0        # oldest tick, dimension 2: full negative
    v[5, 1] = np.nan
    img = heat_image(v, 1.0, lut, columns=20)
    assert img.shape == (3, 20, 4)
    assert np.allclose(img[0, -1], lut[-1]) and np.allclose(img[2, 0], lut[0])
    assert np.allclose(img[1, 0], lut[127], atol=0.02)          # zero is the middle of the map
    assert np.allclose(img[1, 10, :3], 0.2, atol=0.03)          # NaN: dark grey
    out = np.empty((3, 20, 4), np.float32)
    assert heat_image(v, 1.0, lut, columns=20, out=out) is out


def test_heat_image_missing_cells_are_grey_and_the_rest_untouched():
    lut = diverging_lut(256)
    rng = np.random.default_rng(3)
    v = rng.normal(size=(40, 5))
    clean = heat_image(v, 1.5, lut, columns=40)
    v[[2, 9, 30], [0, 4, 1]] = (np.nan, np.inf, -np.inf)
    img = heat_image(v, 1.5, lut, columns=40)
    bad = np.zeros((5, 40), bool)
    bad[[0, 4, 1], [2, 9, 30]] = True
    assert np.array_equal(img[bad], np.tile(np.float32((0.2, 0.2, 0.22, 1.0)), (3, 1)))
    assert np.array_equal(img[~bad], clean[~bad])
    assert lut.shape == (256, 4)                                # the caller's table is not extended


def test_latent_scale():
    assert latent_scale(np.zeros((5, 3))) == 0.5
    assert latent_scale(np.full((5, 3), 4.0)) == pytest.approx(4.0)
    assert latent_scale(np.array([np.nan])) == 1.0


# -- search panels --------------------------------------------------------------------------------

def test_candidate_rows_sort_and_colour_fractions(dbf):
    db, _ = dbf
    c = Candidates(frames=np.array([10, 2000, 30]), costs=np.array([1.0, 3.0, 2.0], np.float32),
                   channel_costs=np.array([[0.5, 0.5], [2.0, 1.0], [0.1, 1.9]], np.float32),
                   bias=np.zeros(3, np.float32), channel_names=["a", "b"])
    rows = candidate_rows(c, db)
    assert [r["rank"] for r in rows] == [1, 2, 3] and rows[1]["frame"] == 2000
    assert rows[0]["clip"] != "-" and rows[0]["t"] >= 0
    for r in rows:   # the candidates show the tags of their range
        assert r["tags"] == ", ".join(db.tags_of(r["frame"])) and r["tags"]
    assert [r["frame"] for r in sort_rows(rows, "total", descending=True)] == [2000, 30, 10]
    assert [r["frame"] for r in sort_rows(rows, "ch1")] == [10, 2000, 30]
    assert [r["frame"] for r in sort_rows(rows, "frame", descending=True)] == [2000, 30, 10]
    assert column_fractions(rows, "total") == [0.0, 1.0, 0.5]
    assert column_fractions(rows, "ch0")[2] == 0.0
    assert candidate_rows(None) == []
    green, red = cost_color(0.0), cost_color(1.0)
    assert green[1] > green[0] and red[0] > red[1]


def test_frame_label_names_the_clip(dbf):
    db, _ = dbf
    name, t = frame_label(db, int(db.range_starts[1]) + 60)
    assert "mirror" in name and t == pytest.approx(1.0)
    assert frame_label(db, -1)[0] == "-"


def test_rolling_agreement():
    searched = np.array([1, 0, 1, 0, 1, 1], float)
    nn = np.array([5, 5, 7, 7, 9, 9], float)
    got = np.array([5, np.nan, 8, np.nan, 9, 20], float)
    r = rolling_agreement(searched, nn, got, window=10, tolerance=0)
    assert r[0] == 1.0 and r[2] == 0.5 and r[4] == pytest.approx(2 / 3) and r[5] == 0.5
    assert rolling_agreement(searched, nn, got, window=10, tolerance=1)[2] == 1.0
    assert np.isnan(rolling_agreement(np.zeros(3), nn[:3], got[:3], 5)).all()


# -- tuning widgets -------------------------------------------------------------------------------

def test_every_tunable_has_a_widget():
    specs = widget_specs()
    fields = {f.name for f in dataclasses.fields(Tuning)}
    assert {s["field"] for s in specs} == fields
    channels = {s["channel"] for s in specs if s["field"] == "feature_weights"}
    assert channels == set(Tuning().feature_weights)
    assert [s["group"] for s in specs] == sorted((s["group"] for s in specs), key=Tuning.groups().index)
    for s in specs:
        assert s["min"] < s["max"] and s["label"]
        assert s["kind"] in ("float", "int", "bool")


def test_widget_values_reach_the_tuning_object():
    """A slider moved through dearpygui (its value set, its callback fired as a drag fires it) reaches the
    Tuning; a bad value is refused with one line and the widget shows the tuning's value again; a change
    made elsewhere (a group reset) moves the widget through the tuning's change events."""
    import dearpygui.dearpygui as dpg

    from app.command_registry import CommandRegistry
    from app.panels.base import PanelContext
    from app.panels.tuning import TuningPanel

    t = Tuning()
    commands, errors = CommandRegistry(), []
    commands.add("dialog_preset_load", "Load", lambda: None)
    commands.add("dialog_preset_save", "Save", lambda: None)
    commands.add("show_error", "Error", lambda title, message: errors.append(message), args=("title", "message"))
    dpg.create_context()
    try:
        panel = TuningPanel(PanelContext(dpg=dpg, tuning=t, commands=commands, theme=None, engine=None))
        panel.build({})

        def move(tag, value):
            dpg.set_value(tag, value)
            dpg.get_item_callback(tag)(tag, dpg.get_value(tag), dpg.get_item_user_data(tag))

        move("tun_run_forward_speed_m_s", 2.25)
        move("tun_top_k", 12)
        move("tun_ik_enabled", False)
        move("tun_feature_weights__hip_velocity", 0.0)
        assert (t.run_forward_speed_m_s, t.top_k, t.ik_enabled, t.feature_weights["hip_velocity"]) == (2.25, 12, False, 0.0)
        assert panel.state()["changes"] == 4 and errors == []
        move("tun_top_k", 0)                         # below the field's range (a typed value can be)
        assert t.top_k == 12 and dpg.get_value("tun_top_k") == 12 and "'top_k'" in errors[0]
        t.reset_group("speeds")
        assert dpg.get_value("tun_run_forward_speed_m_s") == pytest.approx(3.5)
    finally:
        dpg.destroy_context()
    # what a widget's callback does: Tuning.set, which validates
    t = Tuning()
    t.set("run_forward_speed_m_s", 2.25)
    t.set("top_k", 12)
    t.set("ik_enabled", False)
    t.set("feature_weights", 0.0, channel="hip_velocity")
    assert t.run_forward_speed_m_s == 2.25 and t.top_k == 12 and isinstance(t.top_k, int)
    assert t.ik_enabled is False and t.feature_weights["hip_velocity"] == 0.0
    with pytest.raises(TuningError, match="inertialization_halflife_s"):
        t.set("inertialization_halflife_s", 5.0)
    t.validate()
    assert pretty_label("simulation_velocity_halflife_s") == "velocity halflife"
    assert short_channel_name("left_foot_velocity") == "L foot vel"


# -- layouts --------------------------------------------------------------------------------------

def test_shipped_layouts_hold_every_window_and_differ():
    rects = {}
    for name in layouts.builtin_names():
        lay = layouts.load(name)
        assert lay.path.name == f"{name}.ini"
        code = layouts.BUILTIN[name]
        assert lay.hidden == {k for k, v in code.items() if v is None}
        for key, rect in code.items():
            if rect is not None:
                assert tuple(lay.windows[key]["pos"]) == rect[:2], (name, key)
                assert tuple(lay.windows[key]["size"]) == rect[2:], (name, key)
        rects[name] = {k: tuple(v["pos"]) + tuple(v["size"]) for k, v in lay.windows.items() if k not in lay.hidden}
    assert rects["default"]["viewport"] != rects["compare"]["viewport"] != rects["tuning"]["viewport"]
    assert rects["compare"]["viewport"][2] > rects["default"]["viewport"][2]   # bigger 3D view to compare
    assert "search" in rects["compare"] and "tuning" not in rects["compare"]


def test_broken_layout_files_are_refused(tmp_path):
    cases = {"garbage.ini": "this is not an ini file\n", "empty.ini": "",
             "other.ini": "[Window][###424242]\nPos=1,2\nSize=3,4\n",
             "badpos.ini": "[Window][###10001]\nPos=a,b\nSize=3,4\n"}
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(layouts.LayoutError, match=name):
            layouts.load(str(tmp_path / name))
    (tmp_path / "bin.ini").write_bytes(b"\x00\x01\xff\xfe")
    with pytest.raises(layouts.LayoutError):
        layouts.load(str(tmp_path / "bin.ini"))
    with pytest.raises(layouts.LayoutError, match="no such layout"):
        layouts.load("no-such-layout")


def test_layout_helpers(tmp_path, monkeypatch):
    assert layouts.scaled((800, 22), (800, 878), (1600, 900), (1600, 900)) == ((800, 22), (800, 878))
    pos, size = layouts.scaled((800, 461), (800, 439), (1600, 900), (800, 461))
    assert pos[0] == 400 and size[0] == 400 and abs(pos[1] - 241) <= 1
    text = "[Window][###10001]\nPos=1,2\nSize=300,400\n" + layouts.extra_section(["stats"], (1280, 720))
    lay = layouts.parse(text)
    assert lay.hidden == {"stats"} and lay.reference_size == (1280, 720)
    assert "[LmmStudio]" not in layouts.strip_extra_section(text)
    monkeypatch.setenv("LMM_STUDIO_CONFIG", str(tmp_path / "cfg"))
    assert layouts.user_layout_path() == tmp_path / "cfg" / "layout.ini"
    monkeypatch.delenv("LMM_STUDIO_CONFIG")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    assert layouts.user_config_dir() == tmp_path / "xdg" / "lmm-studio"


# -- small helpers --------------------------------------------------------------------------------

def test_feature_markers_place_features_at_the_character(dbf):
    _, features = dbf
    raw = features.raw[1000]
    norm = features.normalize(raw)
    rot = np.array([np.cos(np.pi / 4), 0.0, np.sin(np.pi / 4), 0.0])   # 90 degrees about +Y
    m = feature_markers(features, norm, np.array([1.0, 0.0, 2.0]), rot, {"hips": np.array([1.0, 0.9, 2.0])})
    left = raw[features.slices[0]]
    expect = np.array([1.0 + left[2], left[1], 2.0 - left[0]])          # +Z -> +X, +X -> -Z
    assert np.allclose(m["points"][0], expect, atol=1e-4)
    assert m["traj"].shape == (3, 3) and m["traj_dirs"].shape == (3, 3)
    assert np.allclose(m["traj"][:, 1], 0.0)
    assert len(m["arrows"][0]) == 3                                       # two feet and the hips


def test_scrub_target_and_frame_times_and_renderer_names():
    h = History(10)
    for i in range(1, 31):
        h.append(Tick(i, i / 60, {}))
    assert scrub_target(h, 30, -5) == 25 and scrub_target(h, 25, -100) == 21 and scrub_target(h, 29, 9) == 30
    ft = FrameTimes(n=4)
    for ms in (10, 20, 30, 40, 50):
        ft.add(ms, {"ui": ms / 2})
    assert ft.median() == 35.0 and ft.fps() == pytest.approx(1000 / 35) and ft.median("ui") == 17.5
    assert np.isnan(ft.median("nothing"))
    assert fmt_bytes(5 * 1024 * 1024) == "5.0 MB"


def test_frame_time_median_and_percentile_are_numpys():
    from app.frame_times import median, percentile

    rng = np.random.default_rng(7)
    for i in range(400):
        a = rng.exponential(20.0, int(rng.integers(1, 260)))
        if i % 4 == 0:
            a = np.round(a)                                     # ties
        for q in (0.0, 50.0, 95.0, 100.0, float(rng.uniform(0, 100))):
            assert percentile(a, q) == float(np.percentile(a, q))
        assert median(a) == float(np.median(a))
    a[3] = np.nan
    assert np.isnan(median(a)) and np.isnan(percentile(a, 95))
    ft = FrameTimes(n=5)
    assert np.isnan(ft.percentile(95))
    for ms in (10, 20, 30, 40, 50, 60):                         # 10 has left the window
        ft.add(ms, {"ui": ms / 2})
    assert ft.percentile(95) == float(np.percentile([20, 30, 40, 50, 60], 95))
    assert ft.percentile(50, "ui") == 20.0


def test_frame_time_series_are_kept_until_the_next_frame():
    """series() hands out one array per part until the next add (the Stats panel, its percentile and
    the medians share it); the next frame's time is in the next answer."""
    ft = FrameTimes(n=3)
    for ms in (10, 20, 30):
        ft.add(ms, {"mm": ms / 10})
    a = ft.series()
    assert a.tolist() == [10.0, 20.0, 30.0] and ft.series() is a        # unchanged: not rebuilt
    assert ft.series("mm").tolist() == [1.0, 2.0, 3.0]
    assert ft.percentile(100) == 30.0 and ft.median() == 20.0
    ft.add(40, {"ui": 5.0})                                           # a frame without an MM step
    assert ft.series().tolist() == [20.0, 30.0, 40.0] and ft.series() is not a
    assert ft.series("mm").tolist() == [1.0, 2.0, 3.0] and ft.series("ui").tolist() == [5.0]
    assert ft.percentile(100) == 40.0 and ft.median() == 30.0
    assert ft.series("nothing").tolist() == []
    for ms in (50, 60, 70, 80):                                      # round the window again
        ft.add(ms, {"mm": ms / 10})
    assert ft.series().tolist() == [60.0, 70.0, 80.0] and ft.series("mm").tolist() == [6.0, 7.0, 8.0]

def test_character_feature_markers_are_the_same_shown_together_or_alone(dbf):
    """The matched frame's and the playing frame's features are denormalised together: each marker is
    where it is when only its own toggle is on."""
    from types import SimpleNamespace

    from app.panels.viewport_scene import CharacterDrawing, character_parts

    db, features = dbf

    class Fake:
        def __init__(self, *a, **k):
            self.args, self.visible = None, True

        def update(self, *a, **k):
            self.args = a

        def prepare(self, positions):
            return positions

    viewer = SimpleNamespace(Skeleton=Fake, Spheres=Fake, Arrows=Fake, Lines=Fake)
    rot = np.array([np.cos(0.3), 0.0, np.sin(0.3), 0.0])
    J = len(db.parents)
    pose = SimpleNamespace(global_positions=np.random.default_rng(3).normal(size=(J, 3)),
                           global_rotations=np.tile(rot, (J, 1)))
    snap = SimpleNamespace(pose=pose, matched_features=features.normalize(features.raw[1000]),
                           current_features=features.normalize(features.raw[2000]))

    def markers(matched, current):
        d = CharacterDrawing(viewer, None, db.parents, (0.5, 0.5, 0.5))
        show = {"ghost": False, "trajectory": False, "matched": matched, "features": current, "contacts": False}
        batch = character_parts(d, snap, np.array([1.0, 0.0, 0.0]), show, features, db, None).markers
        return batch._centers, batch._origins, batch._vectors

    both, alone_m, alone_c = markers(True, True), markers(True, False), markers(False, True)
    for b, m, c in zip(both, alone_m, alone_c):
        assert len(b) == len(m) + len(c) and len(m) and len(c)
        for x, y in zip(b, m + c):                  # matched first, then the playing frame's
            assert np.array_equal(x, y)
    # and where feature_markers puts the playing frame's foot positions
    ref = feature_markers(features, snap.current_features, pose.global_positions[0], rot, {})
    assert np.allclose(alone_c[0][0], ref["points"] + [1.0, 0.0, 0.0], atol=1e-9)

def test_viewport_rotation_shortcuts_are_to_matrix():
    from app.panels.viewport_scene import _rotation_t, _z_axes
    from lmm import quat

    q = quat.normalize(np.random.default_rng(5).normal(size=(300, 4)))
    assert np.array_equal(_z_axes(q), quat.to_matrix(q)[:, :, 2])
    for r in q.astype(np.float32)[:100]:            # poses hold float32 rotations
        assert np.array_equal(_rotation_t(r), quat.to_matrix(np.asarray(r, np.float64)).T)


def test_rolling_agreement_is_the_windowed_rate_and_matches_agreement():
    from app.history import agreement
    from app.panels.search import search_masks

    rng = np.random.default_rng(11)
    for window in (0, 1, 7, 40, 500):
        searched = (rng.random(300) < 0.3).astype(float)
        nn = rng.integers(-1, 50, 300).astype(float)
        got = nn + rng.integers(-2, 3, 300)
        nn[rng.random(300) < 0.05] = np.nan
        got[rng.random(300) < 0.05] = np.inf
        r = rolling_agreement(searched, nn, got, window, tolerance=1)
        for i in range(300):      # each tick by itself: the ticks (i - window, i]
            lo = max(i - window + 1, 0)
            rate, k = agreement(searched[lo:i + 1], nn[lo:i + 1], got[lo:i + 1], 1)
            assert (np.isnan(r[i]) and k == 0) if k == 0 or window == 0 else r[i] == rate
        s, agree = search_masks(searched, nn, got, 1)
        rate, k = agreement(searched, nn, got, 1)
        assert k == int(s.sum()) and rate == int(agree.sum()) / k


def test_recording_paths():
    p = recording_paths("/x/take.bvh", ("mm", "lmm"))
    assert p["mm"].name == "take_mm.bvh" and p["lmm"].name == "take_lmm.bvh" and p["input"].name == "take_input.csv"
    assert recording_paths("/x/run", ("lmm",))["lmm"].name == "run.bvh"


# -- the session, headless ------------------------------------------------------------------------

def test_tick_worker_works_out_the_newest_ghost_pose_trajectory_and_query(dbf):
    from app.tick_worker import TickWorker

    db, features = dbf
    tuning = Tuning()
    controllers, _ = make_controllers(db, features, tuning, with_lmm=False)
    worker = TickWorker(Session(db, features, tuning, controllers))
    try:
        worker.submit([InputState(left_y=1.0)] * 8)
        ticks = [t for t, _ in worker.wait()]
    finally:
        worker.close()
    assert len(ticks) == 8

    def pending(tick, name="matched_pose_positions"):    # the lazy field still holds its function
        return callable(tick.snapshots["mm"].__dict__["_lazy_" + name])

    # the newest tick (what a live view draws) has it, worked out on the worker; older ones stay lazy
    assert not pending(ticks[-1]) and pending(ticks[0])
    # so are its trajectory and query (a tick that did not search makes them on the first read)
    quiet = [t for t in ticks[:-1] if not t.snapshots["mm"].searched]
    assert quiet
    for name in ("trajectory_positions", "trajectory_rotations"):
        assert not pending(ticks[-1], name) and all(pending(t, name) for t in quiet), name
    assert not pending(ticks[-1], "query")      # (the session's history reads every tick's query cost)
    ghost = ticks[-1].snapshots["mm"].matched_pose_positions
    assert ghost.shape == (len(db.parents), 3) and np.isfinite(ghost).all()


def test_session_steps_records_and_replays(dbf, tmp_path):
    from lmm.data import bvh
    from lmm.data.inputs import load_input_csv

    db, features = dbf
    tuning = Tuning()
    controllers, problems = make_controllers(db, features, tuning, with_lmm=False)
    s = Session(db, features, tuning, controllers, history_seconds=1.0)
    assert s.history.capacity == 60 and controllers["mm"].tuning is tuning
    paths = s.start_recording(tmp_path / "take.bvh", ("mm", "lmm"))   # LMM is not running: MM only
    assert set(paths) == {"mm", "input"} and paths["mm"].name == "take.bvh"
    for i in range(90):
        s.step(InputState(left_y=1.0, camera_azimuth=0.0))
    result = s.stop_recording()
    assert isinstance(result, RecordingResult) and result.frames == 90 and result.seconds == pytest.approx(1.5)
    assert result.message == "recorded 1.50 s (90 frames) to take.bvh, take_input.csv; session take.lmmsession"
    written = result.paths
    assert written == paths
    assert s.history.newest_tick == 90 and len(s.history) == 60
    anim = bvh.load(written["mm"])
    assert anim.n_frames == 90 and anim.n_joints == db.n_bones - 1   # the simulation bone is left out
    pos = anim.global_positions()
    assert np.linalg.norm(pos[-1, 0] - pos[0, 0]) > 50.0        # centimetres: it ran forward
    log = load_input_csv(written["input"])
    assert log.n_rows >= 1 and log.at(0.0).left_y == 1.0 and log.at(1.4).left_y == 1.0
    # replaying the log restarts the characters and feeds the log
    s.replay(log)
    assert s.tick == 0 and len(s.history) == 0
    t = s.step(s.input_for_next_tick(InputState()))
    assert t.extra["input"].left_y == 1.0
    mem = s.memory["mm"]
    assert mem == controllers["mm"].memory_bytes() and mem["pose data (Y)"] == db.pose_bytes()
    assert set(mem) == {"pose data (Y)", "features (X)", "search index"}


def test_recording_never_overwrites_and_never_leaves_empty_files(dbf, tmp_path):
    from lmm.data import bvh

    db, features = dbf
    tuning = Tuning()
    controllers, _ = make_controllers(db, features, tuning, with_lmm=False)
    controllers["mm2"] = make_controllers(db, features, tuning, with_lmm=False)[0]["mm"]   # two characters
    s = Session(db, features, tuning, controllers)
    # nothing recorded: no file ever appears (files appear with their first flushed frames)
    paths = s.start_recording(tmp_path / "take.bvh", ("mm", "mm2"))
    assert [p.name for p in paths.values()] == ["take_mm.bvh", "take_mm2.bvh", "take_input.csv"]
    assert not any(p.exists() for p in paths.values())
    result = s.stop_recording()
    assert result.paths == {} and result.frames == 0 and result.message == "nothing recorded (0 frames): no file written"
    assert list(tmp_path.iterdir()) == []
    # a file of the take exists (only the input CSV): the next free number, one suffix for every file
    (tmp_path / "take_input.csv").write_text("keep me")
    (tmp_path / "take_001_mm2.bvh").write_text("keep me too")
    counts = []
    for n in (5, 7):
        paths = s.start_recording(tmp_path / "take.bvh", ("mm", "mm2"))
        for _ in range(n):
            s.step(InputState(left_y=1.0))
        result = s.stop_recording()
        assert result.paths == paths and result.frames == n
        counts.append({k: p.name for k, p in paths.items()})
        for name in ("mm", "mm2"):
            assert bvh.load(paths[name]).n_frames == n
    assert counts == [{"mm": "take_002_mm.bvh", "mm2": "take_002_mm2.bvh", "input": "take_002_input.csv"},
                      {"mm": "take_003_mm.bvh", "mm2": "take_003_mm2.bvh", "input": "take_003_input.csv"}]
    assert "to take_003_mm.bvh, take_003_mm2.bvh, take_003_input.csv" in result.message
    assert (tmp_path / "take_input.csv").read_text() == "keep me"
    assert (tmp_path / "take_001_mm2.bvh").read_text() == "keep me too"
    assert not (tmp_path / "take_mm.bvh").exists() and not (tmp_path / "take_001_mm.bvh").exists()
    assert s.stop_recording().paths == {}                      # not recording: nothing to stop


def test_a_full_disk_stops_the_studio_recording_and_keeps_valid_files(dbf, tmp_path, monkeypatch):
    import errno
    import os

    from lmm.data import bvh, stream
    from lmm.data.inputs import load_input_csv

    db, features = dbf
    tuning = Tuning()
    controllers, _ = make_controllers(db, features, tuning, with_lmm=False)
    s = Session(db, features, tuning, controllers)
    paths = s.start_recording(tmp_path / "take.bvh", ("mm",))
    for r in s.recording.writers().values():
        r.flush_interval_s = 0.0                              # flush every tick
    for _ in range(20):
        s.step(InputState(left_y=1.0))
    real_write = os.write

    def full(fd, data):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(stream.os, "write", full)
    monkeypatch.setattr(stream.os, "pwrite", lambda fd, data, off: full(fd, data))
    for _ in range(5):
        s.step(InputState(left_y=1.0))                        # the studio keeps ticking
    assert s.recording is None and "No space left" in s.recording_error
    monkeypatch.setattr(stream.os, "write", real_write)
    result = s.stop_recording()
    assert result.frames == 20 and set(result.paths) == {"mm", "input"}
    assert result.message.startswith("recording stopped by a write error: ") and "take.bvh" in result.message
    assert "\n" not in result.message
    assert bvh.load(paths["mm"]).n_frames == 20 and load_input_csv(paths["input"]).n_rows >= 1
    assert s.stop_recording().message == "not recording"


def test_session_fills_projected_frame_and_mm_latents(dbf):
    """The LMM snapshot names the projector's frame, the MM snapshot the latent of its frame once the
    session has attached the compressor's table (computed in the background)."""
    import time

    db, features = dbf
    tuning = Tuning()
    controllers, problems = make_controllers(db, features, tuning)
    if "lmm" not in controllers:
        pytest.skip(f"no LMM networks: {problems}")
    s = Session(db, features, tuning, controllers)
    s.start_latent_table()
    deadline = time.monotonic() + 120
    while s.latent_table_status.startswith("computing") and time.monotonic() < deadline:
        time.sleep(0.05)
    if s.latent_table_status:
        pytest.skip(s.latent_table_status)
    from lmm.latents import database_latents, load_compressor
    table = database_latents(load_compressor(controllers["lmm"].nets.path.with_name("compressor.npz"), db, features),
                             db)
    projected = []
    for _ in range(30):
        t = s.step(InputState(left_y=1.0))
        mm, lmm = t.snapshots["mm"], t.snapshots["lmm"]
        assert np.allclose(mm.matched_latent, table[mm.matched_frame])
        if lmm.searched:
            projected.append(lmm.projected_frame)
            X = controllers["lmm"].features.normalized.astype(np.float64)
            costs = np.sum((X - lmm.projected_features) ** 2, axis=1)
            assert costs[lmm.projected_frame] == pytest.approx(costs.min(), rel=1e-5, abs=1e-6)
    assert projected and s.history.window("lmm", "projected_frame", s.tick, 30)[np.isfinite(
        s.history.window("lmm", "projected_frame", s.tick, 30))].tolist() == projected
    assert s.history.window("mm", "matched_latent", s.tick, 1)[0].tolist() == pytest.approx(
        table[mm.matched_frame].tolist())
    assert set(s.memory["lmm"]) == {"decompressor", "stepper", "projector"}


def test_reference_clip_loads_and_bad_files_raise(tmp_path):
    from lmm.data.bvh import BVHError

    clip = load_reference_clip(os.path.join(os.path.dirname(__file__), "..", "..", "lmm", "data", "lafan1",
                                            "obstacles3_subject4.bvh.gz"))
    assert clip.positions.shape[1] == 22 and 1.0 < np.ptp(clip.positions[0, :, 1]) < 2.5   # metres
    with pytest.raises(BVHError):
        load_reference_clip(CORPUS / "truncated_frame.bvh")


def test_overlap_and_decimation_helpers():
    tiled = {"a": (0, 0, 100, 100), "b": (100, 0, 200, 100), "c": (0, 100, 200, 200)}
    assert overlapping(tiled) == set()
    tiled["d"] = (150, 50, 250, 150)            # dragged over b and c
    assert overlapping(tiled) == {"b", "c", "d"}
    x = np.arange(1000.0)
    dx, dy = decimate(x, x * 2, 300)
    assert len(dx) <= 300 and dx[-1] == 999.0 and np.all(dy == 2 * dx)
    assert decimate(x[:10], x[:10], 300)[0] is not None and len(decimate(x[:10], x[:10], 300)[0]) == 10


def test_replaying_a_recorded_input_csv_reproduces_the_motion(dbf, tmp_path):
    from lmm.data.inputs import load_input_csv, open_input

    db, features = dbf
    tuning = Tuning()
    controllers, _ = make_controllers(db, features, tuning, with_lmm=False)
    s = Session(db, features, tuning, controllers)
    s.replay(open_input("builtin:zigzag"))
    written = None
    roots = []
    for i in range(120):
        if i == 0:
            s.start_recording(tmp_path / "take.bvh", ("mm",))
        t = s.step(s.input_for_next_tick(InputState()))
        roots.append(t.snapshots["mm"].pose.global_positions[0].copy())
    written = s.stop_recording().paths
    s.replay(load_input_csv(written["input"]))
    again = [s.step(s.input_for_next_tick(InputState())).snapshots["mm"].pose.global_positions[0] for _ in range(120)]
    assert np.allclose(np.array(roots), np.array(again), atol=1e-5)
    assert np.linalg.norm(roots[-1] - roots[0]) > 1.0


# -- new-user fixes -------------------------------------------------------------------------------

def _rows(totals):
    return [{"total": float(v), "channels": [float(v)]} for v in totals]


def test_equal_costs_get_equal_colours():
    # values that read the same (3 decimals) are the same colour; all equal: all green
    same = _rows([1.25, 1.25 + 1e-7, 1.25 + 2e-7, 1.25])
    assert column_fractions(same, "total") == [0.0] * 4
    assert len({cost_color(f) for f in column_fractions(same, "total")}) == 1
    assert cost_color(0.0)[1] > cost_color(0.0)[0]                       # green
    spread = _rows([1.0, 2.0, 2.0, 3.0])
    f = column_fractions(spread, "total")
    assert f == [0.0, 0.5, 0.5, 1.0] and cost_color(f[1]) == cost_color(f[2])
    assert column_fractions(_rows([1.0, float("nan")]), "ch0") == [0.0, 1.0]


def test_character_labels_do_not_overlap():
    anchors = {"mm": (100.0, 50.0), "lmm": (110.0, 52.0), "far": (400.0, 50.0)}
    sizes = {"mm": (120.0, 17.0), "lmm": (30.0, 17.0), "far": (30.0, 17.0)}
    placed = separate_labels(anchors, sizes)
    assert placed["mm"] == (100.0, 50.0) and placed["far"] == (400.0, 50.0)    # not moved when free

    def overlap(a, b):
        (ax, ay), (bx, by) = placed[a], placed[b]
        (aw, ah), (bw, bh) = sizes[a], sizes[b]
        return ax < bx + bw and bx < ax + aw and ay < by + bh and by < ay + ah

    assert not overlap("mm", "lmm") and placed["lmm"][1] >= 50.0 + 17.0
    same = separate_labels({"a": (0, 0), "b": (0, 0), "c": (0, 0)}, {k: (50, 10) for k in "abc"})
    assert sorted(p[1] for p in same.values()) == [0.0, 12.0, 24.0]


def test_controller_time_is_per_tick_and_absent_without_ticks():
    assert per_tick_ms([], ["mm"]) == {}                              # no tick finished: no zero added
    finished = [(None, {"mm": 2.0, "lmm": 1.0}), (None, {"mm": 4.0, "lmm": 3.0})]
    assert per_tick_ms(finished, ["mm", "lmm"]) == {"mm": 3.0, "lmm": 2.0}
    ft = FrameTimes()
    for i in range(10):   # a frame rate above the tick rate: half the frames finish no tick
        ft.add(5.0, per_tick_ms(finished if i % 2 else [], ["mm"]))
    assert ft.median("mm") == 3.0


def test_hidden_windows_note_names_them_and_the_menu():
    assert hidden_note(()) == ""
    note = hidden_note(("stats", "tuning"))
    assert "Tuning" in note and "Stats" in note and "Windows menu" in note


def test_widget_specs_follow_the_live_tuning_keys():
    """A user's own feature channel or tag (added to the tuning by the controllers) gets its slider."""
    t = Tuning()
    t.feature_weights["head_velocity"] = 0.5
    t.tag_bias["sneak"] = 0.0
    specs = widget_specs(t)
    assert {("feature_weights", "head_velocity"), ("tag_bias", "sneak")} <= {(s["field"], s["channel"]) for s in specs}
    assert not any(s["channel"] == "head_velocity" for s in widget_specs())


@pytest.mark.parametrize("line", ["Pos=inf,0", "Pos=0,-inf", "Pos=nan,1", "Pos=1e400,2", "Pos=99999,0",
                                  "Size=100000,300", "Size=0,300", "Size=300,1e308", "Size=3", "Size=1,2,3"])
def test_layout_numbers_out_of_range_are_refused(tmp_path, line):
    path = tmp_path / "bad.ini"
    path.write_text(f"[Window][###10001]\nPos=10,20\nSize=300,200\n{line}\n")
    with pytest.raises(layouts.LayoutError, match=r"bad\.ini: line 4: (Pos|Size)") as e:
        layouts.load(str(path))
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("value", ["inf,900", "0,0", "1600,nan", "100000,900", "-5,900"])
def test_layout_viewport_out_of_range_is_refused(tmp_path, value):
    path = tmp_path / "vp.ini"
    path.write_text("[Window][###10001]\nPos=10,20\nSize=300,200\n" + f"[LmmStudio][Layout]\nViewport={value}\n")
    with pytest.raises(layouts.LayoutError, match=r"vp\.ini: line 5: Viewport"):
        layouts.load(str(path))


def test_scaled_windows_never_exceed_the_viewport():
    pos, size = layouts.scaled((0, 22), (8192, 8192), (320, 240), (1600, 900))
    assert size[0] <= 1600 and size[1] <= 900


def test_a_broken_user_layout_is_set_aside_for_the_default(tmp_path, monkeypatch):
    from app.layouts import LayoutManager

    monkeypatch.setenv("LMM_STUDIO_CONFIG", str(tmp_path))
    user = tmp_path / "layout.ini"
    user.write_text("[Window][###10001]\nPos=inf,0\nSize=300,200\n")
    reports = []
    m = LayoutManager(None, lambda title, msg: reports.append(msg), (1600, 900))
    ini = m.choose(None)
    assert m.layout.name == "default" and not user.exists() and (tmp_path / "layout.ini.bad").exists()
    assert len(reports) == 1 and "layout.ini" in reports[0] and "default" in reports[0]
    reports.clear()
    m.close()
    m = LayoutManager(None, lambda title, msg: reports.append(msg), (1600, 900))
    m.choose(None)                                      # the next start: no report, no loop
    assert m.layout.name == "default" and reports == []
    m.close()
    assert not os.path.exists(os.path.dirname(ini))   # the private working copy is gone


def test_a_user_layout_that_killed_its_start_is_set_aside(tmp_path, monkeypatch):
    from app.layouts import LayoutManager

    monkeypatch.setenv("LMM_STUDIO_CONFIG", str(tmp_path))
    user = tmp_path / "layout.ini"
    user.write_text((layouts.LAYOUT_DIR / "compare.ini").read_text())
    reports = []
    m = LayoutManager(None, lambda title, msg: reports.append(msg), (1600, 900))
    m.choose(None)
    assert m.layout.name == "user" and (tmp_path / "layout.ini.starting").exists() and reports == []
    m.close()                                           # ... and the studio died before started()
    m = LayoutManager(None, lambda title, msg: reports.append(msg), (1600, 900))
    m.choose(None)
    assert m.layout.name == "default" and (tmp_path / "layout.ini.bad").exists() and len(reports) == 1
    assert "did not finish" in reports[0]
    m.close()
    user.write_text((layouts.LAYOUT_DIR / "compare.ini").read_text())
    m = LayoutManager(None, lambda title, msg: reports.append(msg), (1600, 900))
    m.choose(None)
    m.started()                                         # a start that worked leaves no marker
    assert m.layout.name == "user" and not (tmp_path / "layout.ini.starting").exists()
    m.close()


def test_total_error_is_the_sum_of_channel_errors(dbf):
    from types import SimpleNamespace

    from app.panels.features import total_error

    _, features = dbf
    rng = np.random.default_rng(11)
    for _ in range(50):
        a, b = rng.normal(size=27), rng.normal(size=27)
        assert total_error(features, a, b) == float(np.sum(channel_errors(features, a, b)))
    # channels that do not tile the vector (a gap, or a longer vector): the per-channel sums
    gap = SimpleNamespace(slices=[slice(0, 3), slice(4, 6)], layout=[None, None])
    a, b = rng.normal(size=6), rng.normal(size=6)
    assert total_error(gap, a, b) == float(np.sum(channel_errors(gap, a, b)))
    assert total_error(gap, a, b) != float(np.sum((a - b) ** 2))
    short = SimpleNamespace(slices=[slice(0, 3), slice(3, 6)], layout=[None, None])
    a, b = rng.normal(size=8), rng.normal(size=8)
    assert total_error(short, a, b) == float(np.sum(channel_errors(short, a, b)))
    assert np.isclose(total_error(short, a, b), float(np.sum((a[:6] - b[:6]) ** 2)))
    assert not np.isclose(total_error(short, a, b), float(np.sum((a - b) ** 2)))


def test_tag_widgets_follow_the_database_tags():
    """Given the database's tags, the per-tag sliders and checkboxes show those (in its order) and any other
    tag set away from its default; the first of each field carries a heading line."""
    t = Tuning()
    for tag in ("dance", "fall"):
        t.tag_bias.setdefault(tag, 0.0)
        t.tag_excluded.setdefault(tag, False)
    t.tag_excluded["fall"] = True
    t.tag_bias["run"] = 2.0                   # a shipped tag this database lacks, biased: still shown
    specs = widget_specs(t, tags=["dance", "fall", "walk"])
    bias = [s["channel"] for s in specs if s["field"] == "tag_bias"]
    excluded = [s for s in specs if s["field"] == "tag_excluded"]
    assert bias == ["dance", "fall", "walk", "run"]
    assert [s["channel"] for s in excluded] == ["dance", "fall", "walk"]
    assert all(s["kind"] == "bool" and s["label"] == f"exclude {s['channel']}" for s in excluded)
    assert excluded[0]["heading"] and not excluded[1]["heading"]
    assert [s["channel"] for s in widget_specs(t) if s["field"] == "tag_excluded"] == list(t.tag_excluded)
