"""The Tuning panel: a widget for every tunable, values that reach the tuning object through the widgets, and
widgets that follow the live tuning's channels and the database's tags."""
import dataclasses
import pytest
from app.panels.common import short_channel_name
from app.panels.tuning import pretty_label, widget_specs
from lmm.tuning import Tuning, TuningError


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


def test_widget_specs_follow_the_live_tuning_keys():
    """A user's own feature channel or tag (added to the tuning by the controllers) gets its slider."""
    t = Tuning()
    t.feature_weights["head_velocity"] = 0.5
    t.tag_bias["sneak"] = 0.0
    specs = widget_specs(t)
    assert {("feature_weights", "head_velocity"), ("tag_bias", "sneak")} <= {(s["field"], s["channel"]) for s in specs}
    assert not any(s["channel"] == "head_velocity" for s in widget_specs())


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
