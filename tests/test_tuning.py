"""Tuning: typed fields with slider metadata, validation naming the field, JSON presets, groups."""
import dataclasses
import json

import pytest

from lmm.features import DEFAULT_LAYOUT
from lmm.tuning import GROUPS, Tuning, TuningError


def test_every_field_has_slider_metadata():
    fields = dataclasses.fields(Tuning)
    assert len(fields) >= 25
    for f in fields:
        md = f.metadata
        assert md["group"] in GROUPS, f.name
        assert {"min", "max", "unit", "doc"} <= set(md), f.name
        assert md["doc"], f.name
    assert set(Tuning.groups()) == set(GROUPS)
    for g in GROUPS:
        assert Tuning.fields_in(g), g
    Tuning().validate()  # defaults are inside their ranges


def test_reference_defaults_and_feature_weights_from_layout():
    t = Tuning()
    assert t.simulation_velocity_halflife_s == 0.27 and t.inertialization_halflife_s == 0.1
    assert t.search_interval_s == 0.1 and t.exclude_current_window_frames == 20
    assert t.clamp_max_distance_m == 0.15 and t.clamp_max_angle_deg == 90.0
    assert t.feature_weights == {ch.name: ch.weight for ch in DEFAULT_LAYOUT}


def test_round_trip_json(tmp_path):
    t = Tuning()
    t.transition_cost = 0.5
    t.feature_weights["hip_velocity"] = 2.0
    t.ik_enabled = False
    p = tmp_path / "preset.json"
    t.save(p)
    assert Tuning.load(p) == t
    assert json.loads(p.read_text())["transition_cost"] == 0.5


@pytest.mark.parametrize("bad, field", [
    ({"no_such_field": 1}, "no_such_field"),
    ({"transition_cost": "high"}, "transition_cost"),
    ({"ik_enabled": 1}, "ik_enabled"),
    ({"top_k": 2.5}, "top_k"),
    ({"search_interval_s": float("nan")}, "search_interval_s"),
    ({"clamp_max_distance_m": -1.0}, "clamp_max_distance_m"),
    ({"feature_weights": {"hip_velocity": "x"}}, "feature_weights.hip_velocity"),
    ({"feature_weights": [1, 2]}, "feature_weights"),
])
def test_bad_values_name_the_field(bad, field):
    with pytest.raises(TuningError, match=field.replace(".", r"\.")):
        Tuning.from_dict(bad)


def test_load_names_file_and_bad_json(tmp_path):
    p = tmp_path / "broken.json"
    p.write_text('{"transition_cost": 1,,}')
    with pytest.raises(TuningError, match="broken.json.*line 1"):
        Tuning.load(p)
    p.write_text('{"bogus": 1}')
    with pytest.raises(TuningError, match="broken.json.*bogus"):
        Tuning.load(p)


def test_partial_preset_keeps_defaults_and_reset_group():
    t = Tuning.from_dict({"run_forward_speed_m_s": 3.0})
    assert t.run_forward_speed_m_s == 3.0 and t.walk_forward_speed_m_s == Tuning().walk_forward_speed_m_s
    t.ik_unlock_radius_m = 0.4
    t.feature_weights["left_foot_position"] = 3.0
    t.reset_group("ik")
    t.reset_group("features")
    assert t.ik_unlock_radius_m == Tuning().ik_unlock_radius_m
    assert t.feature_weights["left_foot_position"] == 0.75
    assert t.run_forward_speed_m_s == 3.0  # other groups untouched
    with pytest.raises(TuningError):
        t.reset_group("nope")
