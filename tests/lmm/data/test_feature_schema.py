"""The feature schema as data: declared in the manifest (or a file it names), recorded in the database
cache and in trained networks; malformed schemas and networks of another schema get a message that
says what differs and what to do."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from lmm import DEFAULT_MANIFEST
from lmm.data.build import load_or_build
from lmm.data.database import Database
from lmm.data.feature_schema import describe_schema_difference
from lmm.data.manifest import ManifestError
from lmm.data.weights import WeightsError, layout_signature
from lmm.features import DEFAULT_LAYOUT, build_features, schema_of

TAKE = DEFAULT_MANIFEST.parent / "lafan1" / "obstacles3_subject4.bvh.gz"


def manifest(tmp_path: Path, features=None, name="schema.json") -> Path:
    data = {"name": "schema-test", "clips": [{"file": str(TAKE), "ranges": [[2600, 2900]]}]}
    if features is not None:
        data["features"] = features
    path = tmp_path / name
    path.write_text(json.dumps(data))
    return path


def custom_schema(offsets=(10, 30, 50)) -> list[dict]:
    s = schema_of(DEFAULT_LAYOUT)
    for ch in s:
        if ch["kind"].startswith("trajectory"):
            ch["offsets"] = list(offsets)
    s.append({"name": "head_velocity", "kind": "bone_velocity", "bone": "Head", "weight": 0.5})
    return s


def test_default_schema_is_the_shipped_layout(tmp_path):
    db, _ = load_or_build(manifest(tmp_path), cache_dir=tmp_path / "cache")
    assert db.feature_schema == schema_of(DEFAULT_LAYOUT)
    f = build_features(db)
    assert [c.name for c in f.layout] == [c.name for c in DEFAULT_LAYOUT] and f.raw.shape[1] == 27


def test_schema_from_the_manifest_drives_features_query_and_trajectory(tmp_path):
    from lmm.controller import InputState
    from lmm.factory import make_controller

    db, _ = load_or_build(manifest(tmp_path, custom_schema()), cache_dir=tmp_path / "cache")
    f = build_features(db)
    assert f.raw.shape[1] == 27 + 3 and f.layout[-1].bone == "Head" and f.layout[-1].weight == 0.5
    traj = [c for c in f.layout if c.kind == "trajectory_position"][0]
    assert traj.offsets == (10, 30, 50)
    ctrl = make_controller("mm", db, f)
    for _ in range(5):
        pose, snap = ctrl.step(InputState(left_y=1.0), 1.0 / 60.0)
    assert list(snap.trajectory_offsets) == [10, 30, 50]       # the prediction samples the declared times
    assert snap.query.shape == (30,)
    # the schema's weight is the one searched with, and the runtime leaves the shared tuning as it was
    assert ctrl.features.weights[ctrl.features.channel_index("head_velocity")] == 0.5
    assert "head_velocity" not in ctrl.tuning.feature_weights
    ctrl.tuning.name_database_entries({c.name: c.weight for c in f.layout}, db.tag_names)   # as the studio does
    ctrl.step(InputState(left_y=1.0), 1.0 / 60.0)
    assert ctrl.features.weights[ctrl.features.channel_index("head_velocity")] == 0.5
    ctrl.tuning.set("feature_weights", 2.0, channel="head_velocity")     # a slider for the new channel
    ctrl.step(InputState(left_y=1.0), 1.0 / 60.0)
    assert ctrl.features.weights[ctrl.features.channel_index("head_velocity")] == 2.0


def test_schema_in_its_own_file_and_a_change_updates_the_cache(tmp_path):
    cache = tmp_path / "cache"
    (tmp_path / "features.json").write_text(json.dumps({"features": custom_schema((20, 40, 60))}))
    m = manifest(tmp_path, "features.json")
    db, info = load_or_build(m, cache_dir=cache)
    assert not info.cached and db.feature_schema[-1]["name"] == "head_velocity"
    (tmp_path / "features.json").write_text(json.dumps(custom_schema((15, 30, 45))))
    db2, info2 = load_or_build(m, cache_dir=cache)
    assert info2.cached and db2.key == db.key                    # same frames: the key (and networks' tie) stays
    assert Database.load(info2.path).feature_schema == db2.feature_schema   # the cache records the new schema
    assert [c for c in build_features(db2).layout if c.kind == "trajectory_position"][0].offsets == (15, 30, 45)


@pytest.mark.parametrize("features, field, words", [
    ("nope.json", "features", "cannot read the feature schema"),
    ([], "features", "non-empty list"),
    ([{"name": "a", "kind": "bone_spin", "bone": "Hips"}], "features[0].kind", "expected one of"),
    ([{"name": "a", "kind": "bone_velocity"}], "features[0].bone", "needs a bone"),
    ([{"name": "t", "kind": "trajectory_position", "offsets": [40, 20]}], "features[0].offsets", "increasing"),
    ([{"name": "t", "kind": "trajectory_position", "offsets": [0]}], "features[0].offsets", "1 to"),
    ([{"name": "a", "kind": "bone_velocity", "bone": "Hips", "weight": -1}], "features[0].weight", "0 to 10"),
    ([{"name": "a", "kind": "bone_velocity", "bone": "Hips"}] * 2, "features[1].name", "declared twice"),
    ([{"name": "a", "kind": "bone_velocity", "bone": "Hips", "colour": 1}], "features[0].colour", "unknown field"),
])
def test_malformed_schema_names_file_and_field(tmp_path, features, field, words):
    with pytest.raises(ManifestError) as e:
        load_or_build(manifest(tmp_path, features), cache_dir=tmp_path / "cache")
    msg = str(e.value)
    assert f"field '{field}'" in msg and words in msg and "\n" not in msg
    assert "schema.json" in msg or "nope.json" in msg


def test_unknown_bone_is_named_at_build(tmp_path):
    bad = [{"name": "tail_velocity", "kind": "bone_velocity", "bone": "Tail"}]
    with pytest.raises(ManifestError, match=r"features\[0\]\.bone.*no joint or role named 'Tail'"):
        load_or_build(manifest(tmp_path, bad), cache_dir=tmp_path / "cache")


def test_networks_of_another_schema_are_refused_with_what_differs(tmp_path):
    from lmm.learned import DEFAULT_WEIGHTS
    from lmm.data import weights as W

    if not Path(DEFAULT_WEIGHTS).exists():
        pytest.skip("no shipped networks")
    meta = W.load(DEFAULT_WEIGHTS).metadata
    shipped = meta["feature_layout"]
    assert layout_signature(shipped) == layout_signature(schema_of(DEFAULT_LAYOUT))  # networks record the schema
    other = custom_schema((10, 30, 50))
    with pytest.raises(WeightsError) as e:
        W.load(DEFAULT_WEIGHTS, layout_dicts=other)
    msg = str(e.value)
    assert "trained on another feature schema" in msg
    assert "trajectory_position.offsets [20, 40, 60] in the networks, [10, 30, 50] in the data" in msg
    assert "channels only in the data: head_velocity" in msg
    assert "--manifest" in msg and "lmm-studio train all --manifest" in msg


def test_describe_schema_difference_weights_do_not_count():
    a = schema_of(DEFAULT_LAYOUT)
    b = [dict(d, weight=9.0) for d in a]
    assert describe_schema_difference(a, b) == "no difference"
    c = [dict(d) for d in a]
    c[0]["bone"] = "left_toe"
    assert describe_schema_difference(a, c) == "left_foot_position.bone 'left_foot' in the networks, 'left_toe' in the data"
