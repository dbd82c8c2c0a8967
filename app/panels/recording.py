"""Recording & input: record MM, LMM or both to BVH together with the input CSV; replay an input CSV
(or a built-in scenario) into the studio; see which input devices drive the characters; open a
reference BVH and follow it (its derived input drives the characters, :mod:`lmm.follow`), with each
controller's pose error against it plotted over the history and a cursor at the displayed tick."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .base import Panel, View
from .common import COLORS, SHORT, decimate, seconds_axis

BUILTINS = ("circle", "zigzag", "stop-and-go", "strafe", "turns", "random:1")


def default_recording_path() -> Path:
    return Path.cwd() / "recordings" / "take.bvh"


class RecordingPanel(Panel):
    key = "recording"
    commands = ("dialog_record", "dialog_input", "dialog_reference", "open_input", "live_input", "reset_characters",
                "follow", "reference_overlay", "record_start", "record_stop")
    reads = ("devices", "following", "frame", "history", "input_name", "last_recording", "recording", "reference",
             "replay_line", "tick", "tick_number")
    _recording = False

    def __init__(self, ctx):
        super().__init__(ctx)
        self._error_points: dict[str, bool] = {}   # controller -> its pose error curve holds points

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        act = self.ctx.actions
        names = self.ctx.engine.controller_names()
        with self.window(window_kwargs):
            dpg.add_text("Record to BVH (+ input CSV)", color=(200, 200, 210))
            with dpg.group(horizontal=True):
                dpg.add_checkbox(label="MM", tag="rec_mm", default_value=True)
                dpg.add_checkbox(label="LMM", tag="rec_lmm", default_value="lmm" in names, enabled="lmm" in names)
            with dpg.group(horizontal=True):
                dpg.add_input_text(tag="rec_path", default_value=str(default_recording_path()), width=-70)
                dpg.add_button(label="Browse", callback=lambda: act.dialog_record())
            with dpg.group(horizontal=True):
                dpg.add_button(label="Record", tag="rec_button", width=90, callback=self._on_record)
                dpg.add_text("", tag="rec_status", wrap=0)
            dpg.add_separator()
            dpg.add_text("Input", color=(200, 200, 210))
            dpg.add_text("", tag="inp_status", wrap=0)
            with dpg.group(horizontal=True):
                dpg.add_button(label="Replay CSV...", callback=lambda: act.dialog_input())
                dpg.add_combo(BUILTINS, tag="inp_builtin", default_value="circle", width=100)
                dpg.add_button(label="Play", callback=lambda: act.open_input("builtin:" + dpg.get_value("inp_builtin")))
            with dpg.group(horizontal=True):
                dpg.add_button(label="Live input", callback=lambda: act.live_input())
                dpg.add_button(label="Reset characters", callback=lambda: act.reset_characters())
            dpg.add_text("", tag="inp_devices", color=(150, 150, 160), wrap=0)
            dpg.add_separator()
            with dpg.group(horizontal=True):
                dpg.add_button(label="Reference BVH...", callback=lambda: act.dialog_reference())
                dpg.add_text("", tag="ref_status")
            with dpg.group(horizontal=True):
                dpg.add_checkbox(label="Follow reference", tag="ref_follow",
                                 callback=lambda s, a: act.follow(bool(a)))
                dpg.add_checkbox(label="Overlay", tag="ref_overlay",
                                 callback=lambda s, a: act.reference_overlay(bool(a)))
            with dpg.tooltip("ref_follow"):
                dpg.add_text("The reference's root path, turned into stick and buttons, drives both characters\n"
                             "from a reset; the plot shows each one's pose error against the reference\n"
                             "(mean joint rotation angle, radians) at its aligned frame")
            dpg.add_text("", tag="ref_error", wrap=0)
            with dpg.plot(tag="ref_plot", height=140, width=-1, no_menus=True, no_mouse_pos=True, no_title=True,
                          no_box_select=True):
                dpg.add_plot_legend(horizontal=True, outside=True, location=dpg.mvPlot_Location_North)
                dpg.add_plot_axis(dpg.mvXAxis, tag="ref_x")
                with dpg.plot_axis(dpg.mvYAxis, tag="ref_y", label="pose error, rad"):
                    z = [0.0]
                    for name in COLORS:
                        dpg.add_line_series(z, z, tag=f"ref_err_{name}", label=SHORT[name])
                    dpg.add_inf_line_series([0.0], tag="ref_cursor")
        for name in COLORS:
            self.ctx.theme.series(f"ref_err_{name}", COLORS[name], weight=1.5)
        self.ctx.theme.series("ref_cursor", (1.0, 0.86, 0.35), weight=1.5)

    def path(self) -> str:
        return self.dpg.get_value("rec_path")

    def set_path(self, path: str) -> None:
        self.dpg.set_value("rec_path", str(path))

    def which(self) -> tuple[str, ...]:
        names = self.ctx.engine.controller_names()
        return tuple(n for n in ("mm", "lmm") if self.dpg.get_value(f"rec_{n}") and n in names)

    def _on_record(self, *args):
        if self._recording:
            self.ctx.actions.record_stop()
        else:
            self.ctx.actions.record_start(self.path(), self.which())

    def update(self, view: View) -> None:
        dpg = self.dpg
        if view.frame % 30 == 0:   # LMM may have been loaded since (File > Load LMM weights)
            dpg.configure_item("rec_lmm", enabled="lmm" in self.ctx.engine.controller_names())
        rec = view.recording
        self._recording = rec is not None
        self.text.configure("rec_button", label="Stop" if rec is not None else "Record")
        if rec is not None:
            self.text.set("rec_status", f"REC {rec.seconds:5.1f} s -> {', '.join(rec.files)}")
        else:
            self.text.set("rec_status", view.last_recording)
        keyboard = "live: keyboard (WASD/arrows, Shift walk, Ctrl strafe, Q/E camera)"
        self.text.set("inp_status", view.replay_line or keyboard + (" + gamepad" if view.devices else ""))
        self.text.set("inp_devices", "gamepads: " + (", ".join(view.devices) if view.devices else "none connected"))
        self.text.set("ref_status", view.reference or "none")
        follow = self._follow(view)
        self.last = {"recording": rec is not None, "status": self.text.get("rec_status", ""),
                     "input": view.input_name or None, "follow": follow}

    def set_overlay(self, overlay: bool) -> None:
        """Tick the Overlay box (scripts) and draw the reference that way."""
        self.dpg.set_value("ref_overlay", bool(overlay))
        self.ctx.actions.reference_overlay(bool(overlay))

    def _follow(self, view: View) -> dict:
        """The follow controls and the pose error plot: each controller's error over the history (its
        finite points), the cursor at the displayed tick."""
        dpg = self.dpg
        if dpg.get_value("ref_follow") != bool(view.following):
            dpg.set_value("ref_follow", bool(view.following))
        h, dt = view.history, self.ctx.engine.dt
        newest = h.newest_tick
        tick = view.tick
        now = {}
        if tick is not None:
            for name in COLORS:
                if (name, "reference_error") in tick.series:
                    now[name] = (tick.series[(name, "reference_error")], int(tick.series[(name, "reference_frame")]))
        line = "  ".join(f"{SHORT[n]} {e:.3f}" if np.isfinite(e) else f"{SHORT[n]} -" for n, (e, _) in now.items())
        if now:
            frames = ", ".join(str(f) for _, f in now.values())
            line += f" rad at frame {frames}" if any(np.isfinite(e) for e, _ in now.values()) else " (past the end)"
        self.text.set("ref_error", line if view.following else
                      ("not following (tick Follow reference)" if view.reference else ""))
        n = h.capacity
        t = seconds_axis(n, dt)
        top = 0.0
        for name in COLORS:
            # no error series (never followed): nothing to gather, and an empty plot stays as it is
            y = h.window(name, "reference_error", newest, n) \
                if newest >= 0 and h.has_series(name, "reference_error") else None
            ok = None if y is None else np.isfinite(y)
            plotted = ok is not None and bool(ok.any())
            self.text.configure(f"ref_err_{name}", show=plotted)
            if plotted or self._error_points.get(name, True):
                x, v = decimate(t[ok], y[ok], 400) if plotted else ([], [])
                dpg.set_value(f"ref_err_{name}", [np.asarray(x).tolist(), np.asarray(v).tolist()])
                self._error_points[name] = plotted
                if len(v):
                    top = max(top, float(np.max(v)))
        cursor = (view.tick_number - newest) * dt if newest >= 0 else 0.0
        self.text.set("ref_cursor", [[cursor]])
        held = (newest - h.oldest_tick + 1) * dt if newest >= 0 else 0.0      # the ticks since the reset
        self.text.axis_limits("ref_x", -max(min(held, n * dt), 2.0), 0.0)
        self.text.axis_limits("ref_y", 0.0, max(0.5, 1.15 * top))
        return {"following": view.following, "now": {k: {"error_rad": e, "frame": f} for k, (e, f) in now.items()},
                "cursor_s": cursor, "line": line}

    def state(self) -> dict:
        out = dict(self.last)
        dpg = self.dpg
        plotted = {}
        for name in COLORS:      # what the plot holds (read back from its series)
            if dpg.does_item_exist(f"ref_err_{name}") and dpg.get_item_configuration(f"ref_err_{name}")["show"]:
                y = np.asarray(dpg.get_value(f"ref_err_{name}")[1], np.float64)
                plotted[name] = {"points": int(len(y)), "finite": int(np.isfinite(y).sum()),
                                 "min": float(np.nanmin(y)) if len(y) else None,
                                 "max": float(np.nanmax(y)) if len(y) else None,
                                 "mean": float(np.nanmean(y)) if len(y) else None}
        if "follow" in out:
            out["follow"] = dict(out["follow"], plotted=plotted,
                                 cursor_plotted=float(dpg.get_value("ref_cursor")[0][0]))
        return out
