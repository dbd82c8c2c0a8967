"""Timeline and rewind: the last 20 seconds of ticks are kept; pause, scrub (slider or the drag line
in the plot) and step, and the viewport and every panel show the chosen tick. Play resumes the live
simulation from its newest tick.

Keys: Space pauses / plays, comma and period step back / forward one tick while paused, Home goes
back to live.
"""
from __future__ import annotations

import numpy as np

from .common import COLORS, TextCache, View, decimate, window_tag


def scrub_target(history, current: int, delta: int) -> int:
    """The tick ``delta`` ticks from ``current``, kept inside what the history holds (pure)."""
    if history.newest_tick < 0:
        return -1
    return history.clamp(int(current) + int(delta))


class TimelinePanel:
    def __init__(self, dpg, studio):
        self.dpg = dpg
        self.studio = studio
        self.tag = window_tag("timeline")
        self.text = TextCache(dpg)
        self._line_value = 0.0
        self._slider_range = None
        self.last = {}

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        with dpg.window(tag=self.tag, label="Timeline", no_scrollbar=True, **window_kwargs):
            with dpg.group(horizontal=True):
                dpg.add_button(label="Pause", tag="tl_play", width=60, callback=lambda: self.studio.toggle_pause())
                dpg.add_button(label="<", tag="tl_back", width=26, callback=lambda: self.studio.step(-1))
                dpg.add_button(label=">", tag="tl_fwd", width=26, callback=lambda: self.studio.step(1))
                dpg.add_button(label="<<1s", tag="tl_back_s", callback=lambda: self.studio.step(-60))
                dpg.add_button(label="Live", tag="tl_live", callback=lambda: self.studio.go_live())
                dpg.add_slider_int(tag="tl_slider", width=-185, min_value=0, max_value=1, default_value=1,
                                   callback=self._on_slider, format="tick %d")
                dpg.add_text("", tag="tl_status")
            with dpg.plot(tag="tl_plot", height=-1, width=-1, no_menus=True, no_mouse_pos=True, no_title=True,
                          no_box_select=True):
                dpg.add_plot_axis(dpg.mvXAxis, tag="tl_x", label="seconds (0 = newest)")
                with dpg.plot_axis(dpg.mvYAxis, tag="tl_y", label="m/s", auto_fit=True):
                    z = [0.0]
                    dpg.add_line_series(z, z, tag="tl_desired", label="desired speed")
                    for name in COLORS:
                        dpg.add_line_series(z, z, tag=f"tl_speed_{name}", label=f"{name.upper()} speed",
                                            show=name in self.studio.session.controllers)
                dpg.add_drag_line(tag="tl_drag", default_value=0.0, color=(255, 220, 90, 255), thickness=2.0)
        self.studio.theme_series("tl_desired", (0.75, 0.75, 0.75), weight=1.0)
        for name in COLORS:
            self.studio.theme_series(f"tl_speed_{name}", COLORS[name], weight=1.5)

    def _on_slider(self, sender, value):
        self.studio.scrub_to(int(value))

    def update(self, view: View) -> None:
        dpg = self.dpg
        h = view.history
        dt = self.studio.session.dt
        newest = h.newest_tick
        if newest < 0:
            return
        oldest = h.oldest_tick
        if self._slider_range != (oldest, newest):
            self._slider_range = (oldest, newest)
            dpg.configure_item("tl_slider", min_value=int(oldest), max_value=int(newest))
        if dpg.get_value("tl_slider") != view.tick_number and not dpg.is_item_active("tl_slider"):
            dpg.set_value("tl_slider", view.tick_number)
        # the drag line: a user drag moves the scrub position
        line = float(dpg.get_value("tl_drag"))
        want = (view.tick_number - newest) * dt
        if abs(line - self._line_value) > 1e-6 and dpg.is_item_hovered("tl_plot"):
            self.studio.scrub_to(int(round(newest + line / dt)))
            want = line
        dpg.set_value("tl_drag", want)
        self._line_value = want
        n = h.capacity
        t = (np.arange(n) - (n - 1)) * dt
        first = max(0, n - (newest - oldest + 1))
        for name in COLORS:
            running = name in self.studio.session.controllers
            dpg.configure_item(f"tl_speed_{name}", show=running)
            if running:
                y = h.window(name, "speed", newest, n)
                dpg.set_value(f"tl_speed_{name}", list(decimate(t[first:], y[first:], 400)))
        name0 = self.studio.session.names[0]
        dpg.set_value("tl_desired", list(decimate(t[first:], h.window(name0, "desired_speed", newest, n)[first:], 400)))
        dpg.set_axis_limits("tl_x", float(t[0]), 0.0)
        dpg.configure_item("tl_play", label="Play" if view.paused else "Pause")
        held = (newest - oldest + 1) * dt
        mode = "LIVE" if view.live else "PAUSED" if view.paused else "REWIND"
        t_now = view.tick.time_s if view.tick is not None else 0.0
        behind = (view.tick_number - newest) * dt
        status = f"{mode} {t_now:.2f} s" + (f" ({behind:+.2f} s)" if behind else "") + f" | {held:.0f} s held"
        self.text.set("tl_status", status)
        self.last = {"tick": view.tick_number, "newest": newest, "oldest": oldest, "live": view.live,
                     "paused": view.paused}

    def state(self) -> dict:
        return dict(self.last)
