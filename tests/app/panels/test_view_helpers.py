"""Helpers of the 3D view and the timeline: rotation shortcuts, label separation, overlap and decimation, the
scrub target."""
import numpy as np
import pytest
from app.history import History, Tick
from app.panels.common import decimate, fmt_bytes, overlapping
from app.frame_times import FrameTimes
from app.panels.timeline import scrub_target
from app.panels.viewport_labels import separate_labels


def test_viewport_rotation_shortcuts_are_to_matrix():
    from app.panels.viewport_scene import _rotation_t, _z_axes
    from lmm import quat

    q = quat.normalize(np.random.default_rng(5).normal(size=(300, 4)))
    assert np.array_equal(_z_axes(q), quat.to_matrix(q)[:, :, 2])
    for r in q.astype(np.float32)[:100]:            # poses hold float32 rotations
        assert np.array_equal(_rotation_t(r), quat.to_matrix(np.asarray(r, np.float64)).T)


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


def test_overlap_and_decimation_helpers():
    tiled = {"a": (0, 0, 100, 100), "b": (100, 0, 200, 100), "c": (0, 100, 200, 200)}
    assert overlapping(tiled) == set()
    tiled["d"] = (150, 50, 250, 150)            # dragged over b and c
    assert overlapping(tiled) == {"b", "c", "d"}
    x = np.arange(1000.0)
    dx, dy = decimate(x, x * 2, 300)
    assert len(dx) <= 300 and dx[-1] == 999.0 and np.all(dy == 2 * dx)
    assert decimate(x[:10], x[:10], 300)[0] is not None and len(decimate(x[:10], x[:10], 300)[0]) == 10


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
