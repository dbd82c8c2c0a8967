"""Timeline and rewind: the last 20 seconds of ticks are kept; pause, scrub (slider or the drag line
in the plot) and step, and the viewport and every panel show the chosen tick. Play resumes the live
simulation from its newest tick.

Keys: Space pauses / plays, comma and period step back / forward one tick while paused, Home goes
back to live.
"""
from __future__ import annotations

import numpy as np

from .base import Panel, View
from .common import COLORS, decimate, seconds_axis


def scrub_target(history, current: int, delta: int) -> int:
    """The tick ``delta`` ticks from ``current``, kept inside what the history holds (pure)."""
    if history.newest_tick < 0:
        return -1
    return history.clamp(int(current) + int(delta))


#: the speed axis shows at least 0..this (standing still is a flat line at 0, not noise blown up to
#: fill the plot: "2.5e-45 m/s"), and grows in steps of it so the axis does not jitter
SPEED_AXIS_STEP_M_S = 1.0


def speed_axis_top(top_speed: float) -> float:
    """The speed axis' upper limit for curves reaching ``top_speed`` (m/s): the next whole step above
    it, with a little room, at least one step."""
    steps = np.ceil(max(float(top_speed), 0.0) * 1.05 / SPEED_AXIS_STEP_M_S)
    return float(max(steps, 1.0) * SPEED_AXIS_STEP_M_S)


def _peak(values) -> float:
    finite = np.asarray(values, np.float64)
    finite = finite[np.isfinite(finite)]
    return float(finite.max()) if finite.size else 0.0


class TimelinePanel(Panel):
    key = "timeline"
    commands = ("toggle_pause", "step", "live", "scrub")
    reads = ("history", "live", "mode", "paused", "tick", "tick_number")
    _line_value = 0.0
    _slider_range = None
    _slider_value = None      # the tick this panel last put in the slider
    _slider_held = False      # the user holds the slider (its activated / deactivated events)

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        act = self.ctx.actions
        second = int(round(1.0 / self.ctx.engine.dt))
        with self.window(window_kwargs, no_scrollbar=True):
            with dpg.group(horizontal=True):
                dpg.add_button(label="Pause", tag="tl_play", width=60, callback=lambda: act.toggle_pause())
                dpg.add_button(label="<", tag="tl_back", width=26, callback=lambda: act.step(-1))
                dpg.add_button(label=">", tag="tl_fwd", width=26, callback=lambda: act.step(1))
                dpg.add_button(label="<<1s", tag="tl_back_s", callback=lambda: act.step(-second))
                dpg.add_button(label="Live", tag="tl_live", callback=lambda: act.live())
                dpg.add_slider_int(tag="tl_slider", width=-185, min_value=0, max_value=1, default_value=1,
                                   callback=self._on_slider, format="tick %d")
                # whether the user holds the slider, from dearpygui's events (asking each frame costs
                # tens of microseconds in a studio of thousands of items)
                with dpg.item_handler_registry(tag="tl_slider_handlers"):
                    dpg.add_item_activated_handler(callback=lambda: setattr(self, "_slider_held", True))
                    dpg.add_item_deactivated_handler(callback=lambda: setattr(self, "_slider_held", False))
                dpg.bind_item_handler_registry("tl_slider", "tl_slider_handlers")
                dpg.add_text("", tag="tl_status")
            with dpg.plot(tag="tl_plot", height=-1, width=-1, no_menus=True, no_mouse_pos=True, no_title=True,
                          no_box_select=True):
                dpg.add_plot_axis(dpg.mvXAxis, tag="tl_x", label="seconds (0 = newest)")
                with dpg.plot_axis(dpg.mvYAxis, tag="tl_y", label="m/s"):
                    z = [0.0]
                    dpg.add_line_series(z, z, tag="tl_desired", label="desired speed")
                    for name in COLORS:
                        dpg.add_line_series(z, z, tag=f"tl_speed_{name}", label=f"{name.upper()} speed",
                                            show=name in self.ctx.engine.controller_names())
                    for name in COLORS:     # markers: transitions at the top, flagged quality moments at the bottom
                        dpg.add_scatter_series(z, z, tag=f"tl_trans_{name}", label=f"{name.upper()} transitions",
                                               show=False)
                        dpg.add_scatter_series(z, z, tag=f"tl_flags_{name}", label=f"{name.upper()} pops / knee snaps",
                                               show=False)
                dpg.add_drag_line(tag="tl_drag", default_value=0.0, color=(255, 220, 90, 255), thickness=2.0)
        self.ctx.theme.series("tl_desired", (0.75, 0.75, 0.75), weight=1.0)
        for name in COLORS:
            self.ctx.theme.series(f"tl_speed_{name}", COLORS[name], weight=1.5)
            self.ctx.theme.series(f"tl_trans_{name}", COLORS[name], weight=1.0)
            self.ctx.theme.series(f"tl_flags_{name}", (1.0, 0.35, 0.3), weight=1.0)

    def _on_slider(self, sender, value):
        self.ctx.actions.scrub(int(value))

    def prepare_key(self, view: View) -> tuple:
        return tuple(self.ctx.engine.controller_names())

    def prepare(self, view: View) -> dict:
        """The speed curves of every tick held (they do not follow the scrubbed tick)."""
        h = view.history
        names = self.ctx.engine.controller_names()
        newest, oldest = h.newest_tick, h.oldest_tick
        n = h.capacity
        t = seconds_axis(n, self.ctx.engine.dt)
        first = max(0, n - (newest - oldest + 1))
        speeds = {name: list(decimate(t[first:], h.window(name, "speed", newest, n)[first:], 400))
                  for name in COLORS if name in names}
        wanted = h.window(names[0], "desired_speed", newest, n)[first:]
        desired = list(decimate(t[first:], wanted, 400))
        top = max([_peak(wanted)] + [_peak(h.window(name, "speed", newest, n)[first:]) for name in speeds])
        y_max = speed_axis_top(top)
        # markers: each controller's transitions (the snapshots' flag) along the top, its flagged quality
        # moments (lmm.quality: pops, knee snaps, straight knees) along the bottom
        trans, flags = {}, {}
        for k, name in enumerate(speeds):
            jumped = h.window(name, "transitioned", newest, n)[first:] > 0.5
            trans[name] = (list(t[first:][jumped]), [y_max * (0.96 - 0.05 * k)] * int(jumped.sum()))
            hit = h.window(name, "quality_flag", newest, n)[first:] > 0.5      # NaN (no figure) is not a hit
            flags[name] = (list(t[first:][hit]), [y_max * (-0.02 - 0.02 * k)] * int(hit.sum()))
        return {"speeds": speeds, "desired": desired, "t0": float(t[0]), "y_max": y_max, "trans": trans,
                "flags": flags}

    def update(self, view: View, prepared: dict | None = None) -> None:
        dpg = self.dpg
        h = view.history
        dt = self.ctx.engine.dt
        newest = h.newest_tick
        if newest < 0:
            return
        oldest = h.oldest_tick
        if self._slider_range != (oldest, newest):
            self._slider_range = (oldest, newest)
            dpg.configure_item("tl_slider", min_value=int(oldest), max_value=int(newest))
        if self._slider_value != view.tick_number and not self._slider_held:
            self._slider_value = view.tick_number     # a drag's value becomes the scrubbed tick: set again
            dpg.set_value("tl_slider", view.tick_number)
        # the drag line: a user drag moves the scrub position
        line = float(dpg.get_value("tl_drag"))
        want = (view.tick_number - newest) * dt
        if abs(line - self._line_value) > 1e-6 and dpg.is_item_hovered("tl_plot"):
            self.ctx.actions.scrub(int(round(newest + line / dt)))
            want = line
        if line != want:
            dpg.set_value("tl_drag", want)
        self._line_value = want
        p = prepared if prepared is not None else self.prepare(view)
        for name in COLORS:
            curve = p["speeds"].get(name)
            self.text.configure(f"tl_speed_{name}", show=curve is not None)
            if curve is not None:
                dpg.set_value(f"tl_speed_{name}", curve)
        dpg.set_value("tl_desired", p["desired"])
        for name in COLORS:
            for key, tag in (("trans", f"tl_trans_{name}"), ("flags", f"tl_flags_{name}")):
                xy = p.get(key, {}).get(name)
                self.text.configure(tag, show=bool(xy and xy[0]))
                if xy and xy[0]:
                    dpg.set_value(tag, [list(xy[0]), list(xy[1])])
        self.text.axis_limits("tl_x", p["t0"], 0.0)
        self.text.axis_limits("tl_y", -0.07 * p["y_max"], p["y_max"])
        self.text.configure("tl_play", label="Play" if view.paused else "Pause")
        held = (newest - oldest + 1) * dt
        mode = view.mode
        t_now = view.tick.time_s if view.tick is not None else 0.0
        behind = (view.tick_number - newest) * dt
        status = f"{mode} {t_now:.2f} s" + (f" ({behind:+.2f} s)" if behind else "") + f" | {held:.0f} s held"
        self.text.set("tl_status", status)
        self.last = {"tick": view.tick_number, "newest": newest, "oldest": oldest, "live": view.live,
                     "paused": view.paused,
                     "markers": {key: {name: len(xy[0]) for name, xy in p.get(key, {}).items()}
                                 for key in ("trans", "flags")}}
