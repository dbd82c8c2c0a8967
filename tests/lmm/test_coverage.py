"""Coverage: the PCA map equals a reference, a query lands where its data point is, the speed x turn
rate of a database frame equals that of a character asking for the same trajectory, histograms and the
distance to the data are exact; the ``coverage`` command writes its PNG and JSON, bad input is one line."""
from __future__ import annotations

import json

import numpy as np
import pytest

from lmm import quat
from lmm.coverage import (CoverageError, DataDistance, build_coverage, channel_histograms, database_speed_turn,
                          first_trajectory_dims, fit_pca, frame_tag_categories, query_speed_turn, rescale_query,
                          speed_categories, speed_turn_heatmap, subsample, trajectory_speed_turn)
from lmm.features import DEFAULT_LAYOUT, Channel, Features, layout_slices


def _anisotropic(n=300, d=6, seed=0):
    rng = np.random.default_rng(seed)
    basis, _ = np.linalg.qr(rng.normal(size=(d, d)))
    return (rng.normal(size=(n, d)) * np.array([5.0, 3.0, 1.0, 0.5, 0.2, 0.1])[:d]) @ basis.T + rng.normal(size=d)


def _features(raw, layout=DEFAULT_LAYOUT):
    raw = np.asarray(raw, np.float32)
    slices = layout_slices(layout)
    std = raw.std(axis=0)
    return Features(layout=list(layout), raw=raw, mean=raw.mean(axis=0),
                    channel_std=np.array([std[s].mean() for s in slices], np.float32))


def test_pca_equals_the_covariance_eigenvectors():
    x = _anisotropic()
    pca = fit_pca(x, 3)
    cov = np.cov(x, rowvar=False, bias=True)
    values, vectors = np.linalg.eigh(cov)
    order = np.argsort(values)[::-1][:3]
    assert np.allclose(pca.variance, values[order], rtol=1e-9)
    assert np.allclose(pca.variance_ratio, values[order] / values.sum(), rtol=1e-9)
    # the same axes up to sign, and the sign convention holds: each axis' largest component is positive
    assert np.allclose(np.abs(np.sum(pca.axes * vectors[:, order].T, axis=1)), 1.0, atol=1e-9)
    assert np.all(pca.axes[np.arange(3), np.argmax(np.abs(pca.axes), axis=1)] > 0)
    assert np.allclose(pca.axes @ pca.axes.T, np.eye(3), atol=1e-12)
    assert np.allclose(pca.mean, x.mean(axis=0))


def test_pca_refuses_too_little_data():
    with pytest.raises(CoverageError):
        fit_pca(np.zeros((1, 4)))


def test_a_query_is_projected_onto_its_own_point_and_a_plane_point_onto_its_coordinates():
    x = _anisotropic()
    pca = fit_pca(x)
    xy = pca.project(x)
    assert np.allclose(pca.project(x[17]), xy[17])
    on_plane = pca.mean + 2.5 * pca.axes[0] - 1.25 * pca.axes[1]
    assert np.allclose(pca.project(on_plane), [2.5, -1.25])
    # the variance of the projected points is the explained variance
    assert np.allclose(xy.var(axis=0), pca.variance)


def test_a_query_normalised_with_other_weights_lands_on_the_same_point():
    rng = np.random.default_rng(1)
    f = _features(rng.normal(size=(400, 27)) * rng.uniform(0.1, 3.0, size=27))
    map_scale = f.inv_scale.copy()
    raw_query = f.raw[5] + 0.1
    on_map = f.normalize(raw_query)
    f.set_weights({"trajectory_direction": 3.0, "hip_velocity": 0.25})
    other = f.normalize(raw_query)
    assert not np.allclose(other, on_map)
    assert np.allclose(rescale_query(other, f.inv_scale, map_scale), on_map, atol=1e-5)
    # a channel weighted 0 carries nothing: it comes back as the data's mean (0 once normalised)
    f.set_weights({"hip_velocity": 0.0})
    back = rescale_query(f.normalize(raw_query), f.inv_scale, map_scale)
    s = f.slices[f.channel_index("hip_velocity")]
    assert np.all(back[s] == 0.0)


def test_trajectory_speed_and_turn_rate_by_hand():
    third = 1.0 / 3.0
    a = np.radians(30.0)
    speed, turn = trajectory_speed_turn([[0.0, 1.0], [0.6, 0.8]], [[np.sin(a), np.cos(a)], [0.0, 1.0]], third)
    assert np.allclose(speed, [3.0, 3.0]) and np.allclose(turn, [90.0, 0.0])
    _, turn = trajectory_speed_turn([0.0, 1.0], [-np.sin(a), np.cos(a)], third)
    assert turn == pytest.approx(-90.0)


def test_a_character_asking_for_a_frames_trajectory_gets_that_frames_speed_and_turn(db, features):
    """One definition: a query whose predicted trajectory is exactly database frame f's future lands in
    frame f's heat map cell with the same numbers."""
    speed, turn = database_speed_turn(features, db.fps)
    _, _, offset = first_trajectory_dims(features.layout)
    g_rot, g_pos = db.global_transforms()
    rng = np.random.default_rng(2)
    frames = rng.choice(db.n_frames, 40, replace=False)
    for f in frames:
        fut = int(db.future_frame(f, offset))
        s, t = query_speed_turn(g_pos[[fut], 0], g_rot[[fut], 0], [offset], g_pos[f, 0], g_rot[f, 0], offset, db.fps)
        assert s == pytest.approx(speed[f], abs=1e-4) and t == pytest.approx(turn[f], abs=1e-2)
    # a character turning on the spot at a known rate
    yaw = np.radians(45.0)
    q = quat.from_axis_angle(np.array([0.0, 1.0, 0.0]), np.array(yaw))
    s, t = query_speed_turn(np.array([[0.0, 0.0, 0.0]]), q[None], [offset], np.zeros(3), quat.identity(), offset,
                            db.fps)
    assert s == pytest.approx(0.0) and t == pytest.approx(45.0 / (offset / db.fps))
    # an offset the trajectory does not hold: nothing to say
    assert np.isnan(query_speed_turn(g_pos[[0], 0], g_rot[[0], 0], [offset], g_pos[0, 0], g_rot[0, 0], offset + 1,
                                     db.fps)[0])


def test_heatmap_counts_every_frame_once_in_seconds_and_clamps_outliers():
    speed = np.array([0.1, 0.1, 2.6, 99.0, -1.0])
    turn = np.array([0.0, 5.0, -100.0, 1000.0, -1000.0])
    hm = speed_turn_heatmap(speed, turn, fps=10.0, speed_edges=(0, 1, 2, 3), turn_edges=(-180, -90, 0, 90, 180))
    assert hm.seconds.sum() == pytest.approx(0.5)
    assert hm.seconds[0, 2] == pytest.approx(0.2)       # both slow frames: 0 <= turn < 90
    assert hm.seconds[2, 0] == pytest.approx(0.1)       # 2.6 m/s, -100 deg/s
    assert hm.seconds[2, 3] == pytest.approx(0.1)       # clamped into the top right cell
    assert hm.seconds[0, 0] == pytest.approx(0.1)       # clamped into the bottom left cell
    assert hm.cell(2.6, -100.0) == (2, 0) and hm.cell(50.0, 500.0) == (2, 3)
    assert hm.seconds_at(0.1, 1.0) == pytest.approx(0.2) and np.isnan(hm.seconds_at(float("nan"), 0.0))


def test_histograms_hold_every_frame_of_every_dimension():
    rng = np.random.default_rng(3)
    f = _features(rng.normal(size=(500, 27)))
    f.raw[:, 4] = 1.0                                   # a constant dimension still gets a histogram
    hists = channel_histograms(f, bins=16)
    assert [h.name for h in hists] == f.names
    assert sum(h.counts.shape[0] for h in hists) == 27
    for h in hists:
        assert h.counts.shape[1] == 16 and np.all(h.counts.sum(axis=1) == 500)
        assert np.all(np.diff(h.edges, axis=1) > 0)
    assert hists[0].dims == ["x", "y", "z"] and hists[5].dims == ["x+20", "z+20", "x+40", "z+40", "x+60", "z+60"]
    assert hists[0].unit == "m" and hists[2].unit == "m/s"


def test_distance_to_data_is_the_exact_nearest_frame_in_search_cost_units():
    rng = np.random.default_rng(4)
    points = rng.normal(size=(3000, 27)).astype(np.float32)
    dd = DataDistance(points)
    for _ in range(20):
        q = rng.normal(size=27) * 1.5
        costs = ((points.astype(np.float64) - q) ** 2).sum(axis=1)
        frame, cost = dd.nearest(q)
        assert frame == int(np.argmin(costs)) and cost == pytest.approx(costs.min(), rel=1e-5)
    assert dd.nearest(points[123]) == (123, pytest.approx(0.0, abs=1e-6))
    assert dd.nearest(np.full(27, np.nan))[0] == -1
    assert DataDistance(np.zeros((0, 27))).nearest(np.zeros(27))[0] == -1


def test_layouts_without_trajectory_channels_are_refused_in_one_line():
    layout = (Channel("left_foot_position", "bone_position", "left_foot"),)
    with pytest.raises(CoverageError, match="trajectory_position and trajectory_direction"):
        first_trajectory_dims(layout)


def test_map_tags_are_each_ranges_rarest_tag(db):
    names, index = frame_tag_categories(db)
    assert index.shape == (db.n_frames,) and names == sorted(names)
    frames_of = {t: int(db.tag_mask(t).sum()) for t in db.tag_names}
    for r in range(0, db.n_ranges, 7):
        tags = db.range_tags[r]
        expected = min(tags, key=lambda t: (frames_of[t], t)) if tags else "untagged"
        assert names[index[db.range_starts[r]]] == expected


def test_speed_classes_and_subsampling():
    labels, idx = speed_categories([0.0, 0.5, 2.2, 9.0])
    assert labels[0] == "0-0.3 m/s" and labels[-1] == "4+ m/s"
    assert idx.tolist() == [0, 1, 3, len(labels) - 1]
    assert subsample(10, 20).tolist() == list(range(10))
    s = subsample(1000, 50)
    assert len(s) == 50 and s[0] == 0 and s[-1] == 999


def test_coverage_of_the_shipped_database(db, features):
    cov = build_coverage(db, features)
    assert cov.map_xy.shape == (db.n_frames, 2)
    assert cov.heatmap.seconds.sum() == pytest.approx(db.n_frames / db.fps)
    assert 0.0 < cov.pca.variance_ratio.sum() <= 1.0
    # a database frame's own query is on its own point and 0 from the data
    assert np.allclose(cov.project_query(features.normalized[1000]), cov.map_xy[1000], atol=1e-5)
    d = cov.to_dict()
    assert {"pca", "speed_turn", "histograms", "map_density", "frames"} <= set(d)
    json.dumps(d)


# -----------------------------------------------------------------------------------------------
# the command
# -----------------------------------------------------------------------------------------------

def test_coverage_cli_writes_png_and_json(tmp_path, capsys):
    from PIL import Image

    from app.cli import main

    png, out = tmp_path / "cov.png", tmp_path / "cov.json"
    assert main(["coverage", "--png", str(png), "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert len(data["pca"]["axes"]) == 2 and len(data["pca"]["axes"][0]) == len(data["dims"]) == 27
    assert data["dims"][0] == "left_foot_position.x" and data["dims"][-1] == "trajectory_direction.z+60"
    assert data["pca"]["explained_variance_ratio"][0] >= data["pca"]["explained_variance_ratio"][1] > 0
    hm = data["speed_turn"]
    assert np.asarray(hm["seconds"]).shape == (len(hm["speed_edges_m_s"]) - 1, len(hm["turn_edges_deg_s"]) - 1)
    assert [h["channel"] for h in data["histograms"]] == data["channels"]
    assert sum(np.asarray(h["counts"]).shape[0] for h in data["histograms"]) == len(data["pca"]["mean"])
    img = Image.open(png)
    assert img.size == (1500, 1120)
    pixels = np.asarray(img.convert("RGB"))
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 50      # drawn, not a blank image
    assert "PC1" in capsys.readouterr().out


def test_coverage_cli_bad_input_is_one_line(tmp_path, capsys):
    from app.cli import main

    assert main(["coverage"]) == 2
    err = capsys.readouterr().err.strip()
    assert "nothing to write" in err and "\n" not in err
    missing = tmp_path / "missing.json"
    missing.write_text(json.dumps({"name": "m", "clips": [{"file": "nowhere.bvh"}]}))
    assert main(["coverage", "--manifest", str(missing), "--png", str(tmp_path / "x.png")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("lmm-studio coverage: error:") and "nowhere.bvh" in err and "\n" not in err
    assert not (tmp_path / "x.png").exists()
