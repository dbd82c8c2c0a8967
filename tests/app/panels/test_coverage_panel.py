"""The Coverage panel: what it draws (pure functions, no display), and the real studio under Xvfb
showing it, following the tick picked on the timeline."""
from __future__ import annotations

import numpy as np
import pytest

from app.panels.coverage import MAX_CATEGORIES, heat_texture, percentile_in
from lmm.reporting import PALETTE, category_centres, map_bounds, map_categories, map_image
from lmm.coverage import build_coverage, fit_pca

LAYOUT = """[Window][###10001]
Pos=0,22
Size=700,560
Collapsed=0

[Window][###10008]
Pos=0,582
Size=700,318
Collapsed=0

[Window][###10011]
Pos=700,22
Size=900,878
Collapsed=0

[LmmStudio][Layout]
Viewport=1600,900
Hidden=features,latent,search,candidates,tuning,stats,recording
"""
COVERAGE_RECT = (700, 22, 900, 878)
EXCLUDED = ("crouch", "jog", "run", "stop", "strafe", "turn", "walk")   # every shipped tag but idle


@pytest.fixture(scope="module")
def cov(db, features):
    return build_coverage(db, features)


def test_map_image_draws_every_frame_in_its_class_colour(cov):
    labels, cat = map_categories(cov, "tag", MAX_CATEGORIES)
    assert labels == cov.tag_names and len(cat) == cov.n_frames
    img = map_image(cov, cat, 64, 64)
    assert img.shape == (64, 64, 4) and img.dtype == np.float32
    assert map_image(cov, cat, 80, 50).shape == (50, 80, 4)
    # a texel holding only frames of one class is that class's colour (shaded); empty texels are clear
    lo, hi = map_bounds(cov)
    i = int(np.argmin(cov.map_xy[:, 0]))                   # the leftmost frame: alone at the left edge
    col = int(np.floor((cov.map_xy[i, 0] - lo[0]) / (hi[0] - lo[0]) * 64))
    row = 63 - int(np.floor((cov.map_xy[i, 1] - lo[1]) / (hi[1] - lo[1]) * 64))
    assert img[row, col, 3] == 1.0
    rgb = img[row, col, :3]
    assert np.allclose(rgb / rgb.max(), np.array(PALETTE[cat[i]]) / max(PALETTE[cat[i]]), atol=1e-5)
    occupied = img[..., 3] > 0
    assert 0 < occupied.mean() < 1
    assert np.all(img[~occupied, :3] == 0)
    # speed classes: the labels are speeds, the image differs
    speed_labels, speed_cat = map_categories(cov, "speed", MAX_CATEGORIES)
    assert speed_labels[0].endswith("m/s")
    assert not np.allclose(map_image(cov, speed_cat, 64, 64), img)
    centres = category_centres(cov, speed_cat, len(speed_labels))
    fast = speed_labels.index("3-4 m/s")
    sel = (cov.speed_m_s >= 3) & (cov.speed_m_s < 4)
    assert np.allclose(centres[fast], np.median(cov.map_xy[sel], axis=0))


def test_excluded_frames_are_drawn_in_their_own_dim_colour(cov):
    """Frames of excluded tags: a class of their own, in EXCLUDED_COLOR; the other texels keep their class
    colour, and nothing is drawn or dropped beyond that."""
    from lmm.reporting import EXCLUDED_COLOR

    labels, cat = map_categories(cov, "tag", MAX_CATEGORIES)
    excluded = cat == 0                                   # every frame of the first class
    plain, dimmed = map_image(cov, cat, 64, 64), map_image(cov, cat, 64, 64, excluded)
    assert np.array_equal(plain[..., 3], dimmed[..., 3])   # the same texels occupied
    lo, hi = map_bounds(cov)
    ij = np.clip(np.floor((cov.map_xy - lo) / (hi - lo) * 64).astype(int), 0, 63)
    texel = (63 - ij[:, 1]) * 64 + ij[:, 0]
    only_excluded = np.setdiff1d(texel[excluded], texel[~excluded])
    none_excluded = np.setdiff1d(texel[~excluded], texel[excluded])
    assert len(only_excluded) > 10 and len(none_excluded) > 10
    rgb = dimmed[..., :3].reshape(-1, 3)
    grey = np.array(EXCLUDED_COLOR) / max(EXCLUDED_COLOR)
    assert np.allclose(rgb[only_excluded] / rgb[only_excluded].max(axis=1, keepdims=True), grey, atol=1e-5)
    assert np.array_equal(rgb[none_excluded], plain[..., :3].reshape(-1, 3)[none_excluded])
    assert np.array_equal(map_image(cov, cat, 64, 64, np.zeros(cov.n_frames, bool)), plain)


def test_more_tags_than_colours_share_the_last_class(cov):
    many = type(cov)(**{**cov.__dict__, "tag_names": [f"t{i}" for i in range(12)],
                        "frame_tag": np.arange(cov.n_frames) % 12})
    labels, cat = map_categories(many, "tag", MAX_CATEGORIES)
    assert len(labels) == MAX_CATEGORIES and labels[-1] == "5 more"
    assert cat.max() == MAX_CATEGORIES - 1 and (cat == MAX_CATEGORIES - 1).sum() == (many.frame_tag >= 7).sum()


def test_heat_texture_puts_the_fastest_row_first_and_empty_cells_dark_red(cov):
    tex = heat_texture(cov, upscale=2)
    rows, cols = cov.heatmap.seconds.shape
    assert tex.shape == (2 * rows, 2 * cols, 4) and tex.dtype == np.float32
    # the fullest cell (standing still, not turning) is the brightest, in the texture's bottom rows
    i, j = np.unravel_index(np.argmax(cov.heatmap.seconds), cov.heatmap.seconds.shape)
    texel = tex[2 * (rows - 1 - i), 2 * j, :3]
    assert texel.sum() == pytest.approx(tex[..., :3].sum(axis=-1).max())
    empty = np.argwhere(cov.heatmap.seconds == 0)[0]
    assert np.allclose(tex[2 * (rows - 1 - empty[0]), 2 * empty[1], :3], np.array([60, 22, 22]) / 255.0)


def test_percentile_of_a_query_value_in_a_histogram():
    edges = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    counts = np.array([10, 30, 40, 20])
    assert percentile_in(edges, counts, -5.0) == 0.0
    assert percentile_in(edges, counts, 2.0) == pytest.approx(40.0)
    assert percentile_in(edges, counts, 2.5) == pytest.approx(60.0)
    assert percentile_in(edges, counts, 9.0) == 100.0
    assert np.isnan(percentile_in(edges, counts, float("nan")))


# -----------------------------------------------------------------------------------------------
# the studio
# -----------------------------------------------------------------------------------------------

@pytest.mark.gui
def test_coverage_panel_shows_the_live_and_the_picked_tick(run_studio, tmp_path, lmm_weights, features, db):
    from PIL import Image

    layout = tmp_path / "coverage.ini"
    layout.write_text(LAYOUT)
    script = [{"frame": 120, "do": "capture", "label": "live"},
              {"frame": 121, "do": "pause"},
              {"frame": 121, "do": "scrub", "back": 90},
              {"frame": 124, "do": "capture", "label": "scrubbed"},
              {"frame": 125, "do": "coverage", "mode": "speed", "channel": "trajectory_position"},
              {"frame": 128, "do": "capture", "label": "speed"},
              {"frame": 129, "do": "screenshot", "path": str(tmp_path / "coverage.png")},
              {"frame": 130, "do": "live"},
              {"frame": 131, "do": "set_tuning", "field": "feature_weights", "channel": "hip_velocity", "value": 2.0},
              *({"frame": 131, "do": "set_tuning", "field": "tag_excluded", "channel": tag, "value": True}
                for tag in EXCLUDED),
              {"frame": 140, "do": "capture", "label": "reweighted"}]
    args = ["--frames", 145, "--input", "builtin:circle", "--layout", layout]
    args += ["--weights", lmm_weights] if lmm_weights else ["--no-lmm"]
    r = run_studio(*args, script=script)
    assert r.rc == 0, r.stderr[-3000:]
    d = r.dump
    assert d["errors"] == []
    pca = fit_pca(features.normalized)
    live, old = d["labels"]["live"], d["labels"]["scrubbed"]
    for cap in (live, old):
        p = cap["panels"]["coverage"]
        assert p["tick"] == cap["displayed_tick"] and p["mode"] == "tag"
        names = ["mm", "lmm"] if lmm_weights else ["mm"]
        assert sorted(p["queries"]) == sorted(names)
        for name in names:
            q = np.asarray(cap["snapshot_query"][name])
            shown = p["queries"][name]
            # the dot on the map is that tick's query, projected as the data was
            assert np.allclose(shown["xy"], pca.project(q), atol=1e-4)
            # the distance to the data is the exact nearest frame's cost
            costs = ((features.normalized.astype(np.float64) - q) ** 2).sum(axis=1)
            assert shown["cost"] == pytest.approx(costs.min(), rel=1e-4, abs=1e-6)
            assert shown["speed_m_s"] is not None and shown["cell_seconds"] is not None
    assert old["displayed_tick"] < live["displayed_tick"] - 60
    assert not np.allclose(live["panels"]["coverage"]["queries"]["mm"]["xy"],
                           old["panels"]["coverage"]["queries"]["mm"]["xy"])
    speed = d["labels"]["speed"]["panels"]["coverage"]
    assert speed["mode"] == "speed" and speed["channel"] == "trajectory_position"
    assert speed["categories"][0].endswith("m/s") and speed["tick"] == old["displayed_tick"]
    assert len(speed["percentiles"]["mm"]) == 6
    # the map is drawn on a thread: three frames after the switch it shows the speed classes
    assert speed["map"] == {"mode": "speed", "excluded_tags": []} and not speed["map_pending"]
    assert live["panels"]["coverage"]["map"] == {"mode": "tag", "excluded_tags": []}
    # a weight slider moved: the map stays, the query is re-expressed in its units, the distance is
    # measured as the search now measures it
    import copy

    from lmm.coverage import rescale_query

    rew = d["labels"]["reweighted"]
    q = np.asarray(rew["snapshot_query"]["mm"])
    now = copy.deepcopy(features)
    now.set_weights({"hip_velocity": 2.0})
    shown = rew["panels"]["coverage"]["queries"]["mm"]
    assert np.allclose(shown["xy"], pca.project(rescale_query(q, now.inv_scale, features.inv_scale)), atol=1e-4)
    costs = ((now.normalized.astype(np.float64) - q) ** 2).sum(axis=1)
    # every tag but idle excluded by then: motion matching's nearest frame is the nearest idle frame, not
    # the nearest of all (the character is running)
    out = db.tag_mask(EXCLUDED)
    assert shown["cost"] == pytest.approx(costs[~out].min(), rel=1e-4, abs=1e-6)
    assert not out[shown["nearest_frame"]] and costs[out].min() < costs[~out].min()
    # a tag excluded: its frames are counted and named (and drawn dim on the map)
    cov_now = rew["panels"]["coverage"]
    assert cov_now["excluded_tags"] == sorted(EXCLUDED)
    assert cov_now["excluded_frames"] == int(out.sum()) > 0
    assert sorted(cov_now["map"]["excluded_tags"]) == sorted(EXCLUDED) and not cov_now["map_pending"]
    assert cov_now["map_error"] == ""
    assert d["labels"]["live"]["panels"]["coverage"]["excluded_frames"] == 0
    # the window is drawn: the map, the heat map and the histograms make a busy picture
    img = np.asarray(Image.open(tmp_path / "coverage.png").convert("RGB"), np.float32)
    x, y, w, h = COVERAGE_RECT
    region = img[y + 60:y + h - 10, x + 10:x + w - 10]
    assert region.std() > 20.0
    assert len(np.unique(region[::4, ::4].reshape(-1, 3), axis=0)) > 200


def test_history_keeps_each_controllers_query_for_the_trail():
    from types import SimpleNamespace

    from app.history import History, Tick

    h = History(capacity=10)
    for t in range(15):
        snap = SimpleNamespace(query=np.full(3, float(t)), best_cost=0.0, nn_cost=np.nan, projected_cost=np.nan,
                               matched_frame=t, nn_frame=-1, projected_frame=-1, searched=False,
                               forced_search=False, transitioned=False, simulation_velocity=np.zeros(3),
                               desired_velocity=np.zeros(3), pose=SimpleNamespace(global_positions=np.zeros((2, 3))),
                               latent=None, matched_latent=None, timings_us={})
        h.append(Tick(t, t / 60.0, {"mm": snap}))
    w = h.window("mm", "query", 14, 4)
    assert w.shape == (4, 3) and np.allclose(w[:, 0], [11, 12, 13, 14])
    assert np.isnan(h.window("mm", "query", 14, 12)[0]).all()       # older than the buffer holds


def test_the_coverage_is_worked_out_by_a_job_and_a_failure_is_one_line(db, features):
    """The first show starts the job and returns at once (the status says so); once the job has finished,
    the next update takes its outcome. A feature layout without trajectory channels cannot be mapped: one
    line, and no map."""
    import copy
    from types import SimpleNamespace

    from app.panels.coverage import CoveragePanel

    class Dpg:                              # only what the panel calls before the map exists
        def __init__(self):
            self.values = {}

        def set_value(self, item, value):
            self.values[item] = value

    def panel_for(feats):
        dpg = Dpg()
        engine = SimpleNamespace(db=db, features=feats, controller_names=lambda: [])
        return CoveragePanel(SimpleNamespace(dpg=dpg, engine=engine, tuning=None)), dpg

    bones_only = copy.copy(features)
    bones_only.layout = [ch for ch in features.layout if ch.kind.startswith("bone")]
    panel, dpg = panel_for(bones_only)
    assert panel._ensure_coverage() is False
    job = panel._job
    assert job is not None and job.name == "coverage"
    assert panel.error == "" and dpg.values["cov_status"].startswith(
        f"working out the coverage of {db.n_frames:,} frames")
    assert job.wait(60), "the coverage job did not finish in 60 s"
    assert panel.error == ""                # finished, not yet taken: the GUI thread takes it on its update
    assert panel._ensure_coverage() is False
    assert panel.cov is None and panel.error.startswith("no coverage: ") and "\n" not in panel.error
    assert "trajectory" in panel.error, panel.error
    assert dpg.values["cov_status"] == panel.error
    assert panel._ensure_coverage() is False and panel._job is None and not panel.jobs.running()  # not tried again


def test_jobs_deliver_results_errors_and_progress_on_poll_and_drop_cancelled_ones():
    import threading

    from app.jobs import Jobs

    jobs = Jobs()
    got, gate = [], threading.Event()

    def slow(job):
        job.report(0.5, "half way")
        gate.wait(10)
        return 42

    a = jobs.submit("a", slow, on_done=lambda r: got.append(("done", r)),
                    on_progress=lambda f, m: got.append(("progress", f, m)))
    b = jobs.submit("b", lambda job: 1 / 0, on_error=lambda line: got.append(("error", line)))
    c = jobs.submit("c", lambda job: "dropped", on_done=lambda r: got.append(("done", r)))
    c.cancel()
    assert b.wait(10) and c.wait(10)
    for _ in range(100):                   # the progress report of ``a`` arrives before its gate opens
        if a.progress is not None:
            break
        a.wait(0.05)
    assert got == []                       # nothing is delivered on the jobs' threads
    finished = jobs.poll()
    assert {j.name for j in finished} == {"b", "c"} and c.cancelled
    assert got == [("progress", 0.5, "half way"), ("error", "division by zero")]
    gate.set()
    assert jobs.wait(10) and jobs.poll() == [a]
    assert got[-1] == ("done", 42) and jobs.running() == []
