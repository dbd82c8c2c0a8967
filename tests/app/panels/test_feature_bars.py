"""The Feature Vectors panel's data: bars grouped by channel, query / matched / projected values, per-channel
errors; and the 3D view's feature markers."""
from types import SimpleNamespace
import numpy as np
from app.history import History, Tick
from app.panels.base import View
from app.panels.features import bar_layout, bar_values, channel_errors
from app.panels.viewport_scene import feature_markers


def _view(snaps: dict, inspected="mm"):
    h = History(10)
    t = Tick(1, 1 / 60, snaps)
    return View(tick=t, history=h, live=True, paused=False, inspected=inspected)


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
