"""Tuning: one widget per field of :class:`lmm.tuning.Tuning`, generated from the field metadata
(group, range, unit, doc), grouped, with reset-to-default per group and presets saved to / loaded from
JSON files. A widget's callback writes the tuning object through :meth:`lmm.tuning.Tuning.set`, which
validates (the model, not the panel, knows the ranges); both controllers read it on their next step.
The widgets follow the tuning's change events, so a preset, a reset or any other writer shows at once."""
from __future__ import annotations

import dataclasses

from lmm.tuning import Tuning, TuningError

from .base import Panel, View
from .common import short_channel_name

GROUP_TITLES = {
    "simulation": "Simulation springs & stick",
    "speeds": "Speeds",
    "inertialization": "Inertialization",
    "features": "Feature weights",
    "search": "Search: interval, forced search, transition cost, exclusions",
    "sync": "Adjustment & clamping",
    "ik": "Foot locking & IK",
}

OPEN_BY_DEFAULT = ("simulation", "speeds", "features", "search")
CHECKS_PER_ROW = 3
#: labels too long for the panel's label column (the tooltip says the rest)
SHORT_LABELS = {"exclude current window frames": "exclude window", "exclude range end frames": "exclude range end",
                "forced search threshold": "forced search rate", "knee max acceleration": "knee accel limit"}
CHAR_PX = 7          # the width of one character of dearpygui's default font (ProggyClean, 13 px)


def field_kind(f: dataclasses.Field) -> str:
    t = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
    return {"float": "float", "int": "int", "bool": "bool", "dict": "dict"}.get(t, "float")


def pretty_label(name: str) -> str:
    """``simulation_velocity_halflife_s`` -> ``velocity halflife``; the unit is shown by the format."""
    words = name
    for suffix in ("_deg_s2", "_m_s", "_s", "_m", "_deg"):
        if words.endswith(suffix):
            words = words[: -len(suffix)]
            break
    for prefix in ("simulation_", "adjustment_", "clamp_", "ik_", "inertialization_"):
        if words.startswith(prefix) and words != prefix.rstrip("_"):
            words = words[len(prefix):]
    words = words.replace("_", " ")
    return SHORT_LABELS.get(words, words)


#: Per-name fields keyed by the database's tags, and the line shown above their widgets.
TAG_FIELDS = {"tag_bias": "tag bias: cost added to the tag's frames (negative prefers them)",
              "tag_excluded": "excluded tags: never candidates"}


def widget_specs(tuning: Tuning | None = None, tags=None) -> list[dict]:
    """Every widget the panel builds (pure, for tests): group, field, optional channel, kind, range,
    format and tooltip, in group order. Per-name fields (feature weights, tag biases, excluded tags) get
    one slider (a checkbox for true/false entries) per key of ``tuning`` (default ``Tuning()``): the
    controllers add their database's channels and tags, so a user's own feature schema and tags get
    widgets too. With ``tags`` (the database's), the per-tag fields show those tags and any other entry
    set away from its default (so a preset's bias on a tag the data lacks can still be seen and undone).
    The first widget of a per-tag field carries its ``heading``."""
    specs = []
    defaults = tuning if tuning is not None else Tuning()
    fresh = Tuning()
    for group in Tuning.groups():
        for f in Tuning.fields_in(group):
            kind = field_kind(f)
            md = f.metadata
            unit = md.get("unit", "")
            fmt_unit = f" {unit}" if unit and "|" not in unit and unit != "cost" else ""
            if kind == "dict":
                flags = md.get("item") == "bool"
                entries = getattr(defaults, f.name)
                names = list(entries)
                if tags is not None and f.name in TAG_FIELDS:
                    neutral = getattr(fresh, f.name)
                    off = [t for t in names
                           if t not in tags and entries[t] != neutral.get(t, Tuning.neutral_entry(f.name))]
                    names = [t for t in tags if t in entries] + off     # the database's order, then the others
                for i, channel in enumerate(names):
                    label = f"exclude {channel}" if flags else short_channel_name(channel)
                    specs.append({"group": group, "field": f.name, "channel": channel,
                                  "kind": "bool" if flags else "float", "min": md["min"], "max": md["max"],
                                  "label": label, "format": "%.2f", "doc": md.get("doc", ""),
                                  "heading": TAG_FIELDS.get(f.name) if i == 0 else None})
                continue
            fmt = "%d" + fmt_unit.replace("%", "%%") if kind == "int" else "%.3f" + fmt_unit.replace("%", "%%")
            specs.append({"group": group, "field": f.name, "channel": None, "kind": kind, "min": md["min"],
                          "max": md["max"], "label": pretty_label(f.name), "format": fmt,
                          "doc": md.get("doc", "") + (f" ({unit})" if unit else "")})
    return specs


def widget_tag(spec: dict) -> str:
    return f"tun_{spec['field']}" + (f"__{spec['channel']}" if spec.get("channel") else "")


class TuningPanel(Panel):
    key = "tuning"
    commands = ("dialog_preset_load", "dialog_preset_save", "show_error")
    reads = ("tick",)
    _showing = None          # the reopened session's tuning shown at the picked tick (None: the studio's own)

    def __init__(self, ctx):
        super().__init__(ctx)
        self.tuning: Tuning = ctx.tuning
        engine = getattr(ctx, "engine", None)
        db = getattr(engine, "db", None)
        self.specs = widget_specs(self.ctx.tuning, None if db is None else list(db.tag_names))
        self._widgets = {(spec["field"], spec["channel"]): spec for spec in self.specs}
        self.changes = 0
        self.tuning.events.connect(self._on_tuning_change)

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        act = self.ctx.actions
        # the sliders leave room for their longest label (were cut: "exclude current windov"); their
        # handle is thin and see-through, so it never hides the value it sits on ("0.2|7|0 s")
        self._label_px = max(150, CHAR_PX * max((len(s["label"]) for s in self.specs), default=0) + 10)
        with dpg.theme(tag="tun_slider_theme"):
            for kind in (dpg.mvSliderFloat, dpg.mvSliderInt):
                with dpg.theme_component(kind):
                    dpg.add_theme_style(dpg.mvStyleVar_GrabMinSize, 4)
                    dpg.add_theme_color(dpg.mvThemeCol_SliderGrab, (110, 150, 220, 110))
                    dpg.add_theme_color(dpg.mvThemeCol_SliderGrabActive, (150, 185, 250, 160))
        with self.window(window_kwargs):
            with dpg.group(horizontal=True):
                dpg.add_button(label="Load preset...", callback=lambda: act.dialog_preset_load())
                dpg.add_button(label="Save preset...", tag="tun_save_preset", callback=lambda: act.dialog_preset_save())
                dpg.add_button(label="Reset all", callback=self.reset_all)
            dpg.add_text("acts on the next frame of both characters", tag="tun_note", color=(150, 150, 160))
            current_group = None
            header = row = None
            in_row = 0
            for spec in self.specs:
                if spec["group"] != current_group:
                    current_group = spec["group"]
                    header = dpg.add_collapsing_header(label=GROUP_TITLES.get(current_group, current_group),
                                                       default_open=current_group in OPEN_BY_DEFAULT,
                                                       tag=f"tun_group_{current_group}")
                    dpg.add_button(label=f"Reset {current_group}", parent=header, small=True,
                                   callback=self._on_reset_group, user_data=current_group,
                                   tag=f"tun_reset_{current_group}")
                if spec.get("heading"):
                    dpg.add_text(spec["heading"], parent=header, color=(150, 150, 160))
                if spec["kind"] == "bool" and spec["channel"] is not None:
                    # a per-tag checkbox: CHECKS_PER_ROW to a row (a database may have a dozen tags)
                    if row is None or in_row >= CHECKS_PER_ROW:
                        row, in_row = dpg.add_group(horizontal=True, parent=header), 0
                    self._add_widget(spec, row)
                    in_row += 1
                    continue
                row = None
                self._add_widget(spec, header)

    def _add_widget(self, spec: dict, parent) -> None:
        dpg = self.dpg
        tag = widget_tag(spec)
        value = self._value(spec)
        common = dict(tag=tag, parent=parent, label=spec["label"], callback=self._on_change,
                      user_data=(spec["field"], spec["channel"]))
        if spec["kind"] == "bool":
            dpg.add_checkbox(default_value=bool(value), **common)
        elif spec["kind"] == "int":
            dpg.add_slider_int(default_value=int(value), min_value=int(spec["min"]), max_value=int(spec["max"]),
                               format=spec["format"], width=-self._label_px, **common)
            dpg.bind_item_theme(tag, "tun_slider_theme")
        else:
            dpg.add_slider_float(default_value=float(value), min_value=float(spec["min"]),
                                 max_value=float(spec["max"]), format=spec["format"], width=-self._label_px,
                                 **common)
            dpg.bind_item_theme(tag, "tun_slider_theme")
        if spec["doc"]:
            with dpg.tooltip(tag):
                dpg.add_text(spec["doc"], wrap=360)

    def update(self, view: View) -> None:
        """In a reopened session the sliders show the session's tuning at the picked tick, read-only (a
        what-if edits a scratch copy: Search Candidates); back live, the studio's own again."""
        shown = view.tick.extra.get("tuning") if view.tick is not None else None
        if shown is self._showing:
            return
        self._showing = shown
        self.text.set("tun_note", "acts on the next frame of both characters" if shown is None else
                      "the session's tuning at the picked tick (read-only; what if: Search Candidates)")
        for spec in self.specs:
            self.text.configure(widget_tag(spec), enabled=shown is None)
            self._show(spec)

    def _value(self, spec: dict):
        shown = self._showing
        v = shown[spec["field"]] if shown is not None else getattr(self.tuning, spec["field"])
        if spec["channel"] is not None:
            return v.get(spec["channel"], Tuning.neutral_entry(spec["field"]))
        return v

    def _on_change(self, sender, value, user_data):
        field, channel = user_data
        try:
            self.tuning.set(field, value, channel=channel)
            self.changes += 1
        except TuningError as e:
            self.ctx.actions.show_error("Tuning", str(e))
            self._show(self._widgets[(field, channel)])     # the tuning kept its value: so does the widget

    def _on_tuning_change(self, change) -> None:
        """A tuning change event: its widget (when the panel has one and it is built) shows the new value."""
        spec = self._widgets.get((change.field, change.channel))
        if spec is not None and self.dpg.does_item_exist(widget_tag(spec)):
            self._show(spec)

    def _show(self, spec: dict) -> None:
        self.dpg.set_value(widget_tag(spec), self._value(spec))

    def _on_reset_group(self, sender, value, group):
        self.tuning.reset_group(group)

    def reset_all(self, *args):
        for g in Tuning.groups():
            self.tuning.reset_group(g)

    def set_field(self, field: str, value, channel=None) -> None:
        """Set a widget as a user would and fire its callback (the test scripts use this)."""
        spec = next(s for s in self.specs if s["field"] == field and s["channel"] == channel)
        tag = widget_tag(spec)
        self.dpg.set_value(tag, value)
        self.dpg.get_item_callback(tag)(tag, self.dpg.get_value(tag), self.dpg.get_item_user_data(tag))

    def load_preset(self, path) -> None:
        # TuningError with the file and field; a feature channel the running controllers lack is one
        t = Tuning.load(path, channels=list(self.tuning.feature_weights))
        self.tuning.assign(t)   # the database's own tags and channels keep their widgets' entries

    def state(self) -> dict:
        return {"changes": self.changes, "widgets": len(self.specs), "note": self.text.get("tun_note"),
                "values": {widget_tag(spec): self.dpg.get_value(widget_tag(spec)) for spec in self.specs}}
