"""Tuning: typed fields with slider metadata, validation naming the field, JSON presets, groups."""
import dataclasses
import json

import pytest

from lmm.features import DEFAULT_LAYOUT
from lmm.tuning import GROUPS, Tuning, TuningChange, TuningError


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


def test_set_validates_one_field_and_names_it():
    t = Tuning()
    t.set("run_forward_speed_m_s", 2.25)
    t.set("top_k", 12.0)                       # an integer slider value may arrive as a float
    t.set("ik_enabled", False)
    t.set("feature_weights", 0.5, channel="hip_velocity")
    assert t.run_forward_speed_m_s == 2.25 and t.top_k == 12 and isinstance(t.top_k, int)
    assert t.ik_enabled is False and t.feature_weights["hip_velocity"] == 0.5
    cases = [(("inertialization_halflife_s", 5.0), r"'inertialization_halflife_s'.*outside \[0.0, 0.3\]"),
             (("top_k", 2.5), "'top_k': expected an integer"),
             (("ik_enabled", 1), "'ik_enabled': expected true or false"),
             (("no_such_field", 1.0), "unknown tuning field 'no_such_field'"),
             (("feature_weights", 9.0, "hip_velocity"), r"'feature_weights.hip_velocity'.*outside \[0.0, 5.0\]"),
             (("feature_weights", 1.0, "no_channel"), "unknown channel 'no_channel'"),
             (("top_k", 3, "hip_velocity"), "'top_k' has no channels")]
    for args, message in cases:
        before = t.to_dict()
        with pytest.raises(TuningError, match=message):
            t.set(*args)
        assert t.to_dict() == before, args       # a refused value changes nothing
    t.validate()


@pytest.mark.parametrize("content, words", [
    (b"\xff\xfe{\x00}\x00", "not UTF-8 text (byte 0)"),
    (b"[" * 100000 + b"]" * 100000, "nested 100000 levels deep, more than 64 (MAX_JSON_DEPTH)"),
    (b'{"top_k": ' + b"9" * 5000 + b"}", "Exceeds the limit (4300 digits)"),
    (b'{"top_k": ' + b"9" * 4000 + b"}", "tuning field 'top_k': a 4000-digit number is outside [1, 64]"),
    (b'{"transition_cost": 1e999}', "tuning field 'transition_cost': expected a finite number"),
    (b'{"feature_weights": {}}', "tuning field 'feature_weights': empty"),
    (b'[1, 2]', "a tuning preset must be a JSON object, got list"),
    (b'{"top_k": 8', "not valid JSON (line 1, column 12)"),
    (b'{"tag_bias": {"' + b"x" * 300 + b'": 1}}', "names must be strings of 1 to 100 characters"),
])
def test_hostile_presets_are_one_line_errors_naming_the_file(tmp_path, content, words):
    p = tmp_path / "hostile.json"
    p.write_bytes(content)
    with pytest.raises(TuningError) as e:
        Tuning.load(p)
    msg = str(e.value)
    assert msg.startswith(f"{p}: ") and words in msg and "\n" not in msg and len(msg) < 400, msg
    from lmm.errors import InputError
    assert isinstance(e.value, InputError)


def test_preset_size_is_checked_before_reading(tmp_path, monkeypatch):
    import lmm.tuning as tuning

    monkeypatch.setattr(tuning, "MAX_PRESET_BYTES", 10)
    p = tmp_path / "big.json"
    p.write_text('{"top_k": 8, "transition_cost": 0.5}')
    with pytest.raises(TuningError, match="larger than 10 bytes"):
        Tuning.load(p)
    with pytest.raises(TuningError, match="no such tuning preset"):
        Tuning.load(tmp_path / "missing.json")


def test_unknown_feature_channels_are_refused_when_the_channels_are_known(tmp_path):
    p = tmp_path / "typo.json"
    p.write_text(json.dumps({"feature_weights": {"hip_velocty": 2.0}}))
    assert Tuning.load(p).feature_weights["hip_velocty"] == 2.0  # no schema given: kept (custom schemas)
    channels = [ch.name for ch in DEFAULT_LAYOUT]
    with pytest.raises(TuningError, match=r"'feature_weights\.hip_velocty': no such feature channel") as e:
        Tuning.load(p, channels=channels)
    assert str(e.value).startswith(f"{p}: ")
    p.write_text(json.dumps({"feature_weights": {"hip_velocity": 2.0}}))
    assert Tuning.load(p, channels=channels).feature_weights["hip_velocity"] == 2.0


def test_every_change_is_announced_once_with_field_channel_old_and_new():
    t = Tuning()
    seen = []
    t.events.connect(seen.append)
    t.set("stick_deadzone", 0.3)
    t.set("feature_weights", 2.0, channel="hip_velocity")
    t.tag_bias["walk"] = 1.5                      # an entry written in place is announced as well
    t.top_k = 8                                   # unchanged: no event
    t.reset_group("search")
    assert seen == [TuningChange("stick_deadzone", None, 0.2, 0.3),
                    TuningChange("feature_weights", "hip_velocity", 1.0, 2.0),
                    TuningChange("tag_bias", "walk", 0.0, 1.5),
                    TuningChange("tag_bias", "walk", 1.5, 0.0)]
    seen.clear()
    t.assign(Tuning.from_dict({"ik_enabled": False, "tag_excluded": {"run": True}}))
    assert {(c.field, c.channel, c.new) for c in seen} == {
        ("stick_deadzone", None, 0.2), ("feature_weights", "hip_velocity", 1.0),
        ("ik_enabled", None, False), ("tag_excluded", "run", True)}


def test_replaying_the_changes_backwards_gives_the_starting_tuning_back():
    """What an undo needs: each event carries enough to revert it (old None: the entry was added)."""
    t = Tuning()
    start = t.to_dict()
    seen = []
    t.events.connect(seen.append)
    t.set("search_interval_s", 0.5)
    t.set("feature_weights", 0.0, channel="hip_velocity")
    t.tag_bias.setdefault("dance", 0.0)
    t.set("tag_bias", -1.0, channel="dance")
    t.assign(Tuning.from_dict({"top_k": 3}))
    t.events.disconnect(seen.append)
    for c in reversed(seen):
        if c.channel is None:
            setattr(t, c.field, c.old)
        elif c.old is None:
            del getattr(t, c.field)[c.channel]
        else:
            getattr(t, c.field)[c.channel] = c.old
    assert t.to_dict() == start
    assert [(c.field, c.channel) for c in seen[:4]] == [("search_interval_s", None), ("feature_weights", "hip_velocity"),
                                                       ("tag_bias", "dance"), ("tag_bias", "dance")]


def test_a_dropped_subscriber_is_not_kept_alive_nor_called():
    t = Tuning()

    class Listener:
        calls = 0

        def on(self, change):
            Listener.calls += 1

    listener = Listener()
    t.events.connect(listener.on)
    t.set("top_k", 9)
    del listener
    t.set("top_k", 10)
    assert Listener.calls == 1 and len(t.events) == 0


def test_naming_a_databases_entries_changes_no_value_the_runtime_reads():
    t = Tuning()
    t.name_database_entries({"hip_velocity": 9.0, "head_velocity": 0.5}, ["walk", "dance"])
    assert t.feature_weights["hip_velocity"] == 1.0 and t.feature_weights["head_velocity"] == 0.5
    assert t.tag_bias["dance"] == 0.0 and t.tag_excluded["dance"] is False
    t.set("tag_bias", 2.0, channel="dance")      # now its slider can set it
    assert t.tag_bias["dance"] == 2.0


def test_controllers_read_the_tuning_and_never_write_into_it(db, features):
    """A controller's defaults for the entries a tuning does not name are its own (the schema's weights,
    no tag bias); a feature weight change reaches it by an event at its next step."""
    from lmm.controller import InputState
    from lmm.mm import MotionMatchingController

    t = Tuning.from_dict({"feature_weights": {features.layout[0].name: 2.0}})
    del t.feature_weights[features.layout[1].name]
    before = t.to_dict()
    c = MotionMatchingController(db, features, t)
    c.step(InputState(left_y=1.0), 1 / 60)
    assert t.to_dict() == before
    assert c.features.weights[0] == 2.0 and c.features.weights[1] == features.weights[1]
    t.set("feature_weights", 3.0, channel=features.layout[0].name)
    c.step(InputState(left_y=1.0), 1 / 60)
    assert c.features.weights[0] == 3.0 and t.to_dict() != before
