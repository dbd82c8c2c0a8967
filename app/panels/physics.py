"""Physics: a simulated ragdoll (lmm.physics.ragdoll) tracks each controller; this panel plots, for MM and
LMM side by side, the root residual force it needs (fraction of body weight), its tracking error (mean
joint position error, cm) and its foot contacts over the last seconds, and switches the ragdolls, their
residual force, which one the 3D view draws, and resets them. Without the optional ``mujoco`` package the
panel says how to install it."""
from __future__ import annotations

import numpy as np

from .base import Panel, View
from .common import COLORS, SHORT, decimate

WINDOW_S = 10.0
CONTACT_ROWS = [(name, side) for name in COLORS for side in ("left", "right")]   # top to bottom


class PhysicsPanel(Panel):
    key = "physics"
    commands = ("ragdoll", "reset_ragdolls")
    reads = ("history", "physics_status", "ragdoll", "tick_number")

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        act = self.ctx.actions
        with self.window(window_kwargs):
            dpg.add_text("", tag="phys_status", wrap=0, color=(240, 190, 90))
            with dpg.group(horizontal=True, tag="phys_controls"):
                dpg.add_checkbox(label="Simulate", tag="phys_enabled", default_value=True,
                                 callback=lambda s, a: act.ragdoll("enabled", bool(a)))
                dpg.add_checkbox(label="Residual force", tag="phys_residual", default_value=True,
                                 callback=lambda s, a: act.ragdoll("residual", bool(a)))
                dpg.add_text("Draw:")
                dpg.add_radio_button([SHORT[n] for n in COLORS], tag="phys_drawn", horizontal=True,
                                     default_value=SHORT["mm"], callback=self._on_drawn)
                dpg.add_button(label="Reset", tag="phys_reset", callback=lambda: act.reset_ragdolls())
            with dpg.tooltip("phys_residual"):
                dpg.add_text("A force and torque at the root that pull the ragdoll towards the tracked\n"
                             "pose (the 'hand of god'); its size is what the motion needs beyond what\n"
                             "the joints and the feet on the floor give. Off: the ragdoll balances by\n"
                             "tracking alone and falls when it cannot (it stands up again after 1 s).")
            dpg.add_text("", tag="phys_numbers")
            for tag, label in (("res", "residual (BW)"), ("err", "error (cm)")):
                with dpg.plot(tag=f"phys_{tag}_plot", height=150, width=-1, no_menus=True, no_mouse_pos=True,
                              no_box_select=True, no_title=True):
                    dpg.add_plot_legend(location=dpg.mvPlot_Location_NorthWest)
                    dpg.add_plot_axis(dpg.mvXAxis, tag=f"phys_{tag}_x", no_tick_labels=tag == "res")
                    with dpg.plot_axis(dpg.mvYAxis, tag=f"phys_{tag}_y", label=label):
                        for name in COLORS:
                            dpg.add_line_series([0.0], [0.0], tag=f"phys_{tag}_{name}", label=SHORT[name])
                for name in COLORS:
                    self.ctx.theme.series(f"phys_{tag}_{name}", COLORS[name], weight=1.5)
            with dpg.plot(tag="phys_contact_plot", height=-1, width=-1, no_menus=True, no_mouse_pos=True,
                          no_box_select=True, no_title=True):
                dpg.add_plot_axis(dpg.mvXAxis, tag="phys_contact_x", label="seconds (0 = displayed tick)")
                with dpg.plot_axis(dpg.mvYAxis, tag="phys_contact_y", label="foot contacts"):
                    for name, side in CONTACT_ROWS:
                        dpg.add_line_series([0.0], [0.0], tag=f"phys_contact_{name}_{side}")
                ticks = tuple((f"{SHORT[n]} {s[0].upper()}", float(len(CONTACT_ROWS) - 1 - i) + 0.4)
                              for i, (n, s) in enumerate(CONTACT_ROWS))
                dpg.set_axis_ticks("phys_contact_y", ticks)
                dpg.set_axis_limits("phys_contact_y", -0.3, len(CONTACT_ROWS))
            for name, side in CONTACT_ROWS:
                self.ctx.theme.series(f"phys_contact_{name}_{side}", COLORS[name], weight=2.0)

    def _on_drawn(self, sender, value):
        for name in COLORS:
            if SHORT[name] == value:
                self.ctx.actions.ragdoll("drawn", name)

    def update(self, view: View) -> None:
        dpg = self.dpg
        running = not view.physics_status
        self.text.set("phys_status", view.physics_status)
        dpg.configure_item("phys_status", show=not running)
        for tag in ("phys_controls", "phys_numbers", "phys_res_plot", "phys_err_plot", "phys_contact_plot"):
            dpg.configure_item(tag, show=running)
        if not running:
            self.last = {"status": view.physics_status}
            return
        settings = view.ragdoll
        if dpg.get_value("phys_enabled") != settings.get("enabled", True):
            dpg.set_value("phys_enabled", bool(settings.get("enabled", True)))
        if dpg.get_value("phys_residual") != settings.get("residual", True):
            dpg.set_value("phys_residual", bool(settings.get("residual", True)))
        h = view.history
        end = view.tick_number
        n = int(round(WINDOW_S / self.ctx.engine.dt))
        t = (np.arange(n) - (n - 1)) * self.ctx.engine.dt
        names = [nm for nm in self.ctx.engine.controller_names() if nm in COLORS]
        shown = {}
        for name in COLORS:
            on = name in names
            for tag in ("res", "err"):
                dpg.configure_item(f"phys_{tag}_{name}", show=on)
            for side in ("left", "right"):
                dpg.configure_item(f"phys_contact_{name}_{side}", show=on)
            if not on:
                continue
            res = h.window(name, "ragdoll_residual_bw", end, n)
            err = h.window(name, "ragdoll_error_cm", end, n)
            dpg.set_value(f"phys_res_{name}", list(decimate(t, res, 400)))
            dpg.set_value(f"phys_err_{name}", list(decimate(t, err, 400)))
            for side in ("left", "right"):
                row = len(CONTACT_ROWS) - 1 - CONTACT_ROWS.index((name, side))
                c = h.window(name, f"ragdoll_contact_{side}", end, n)
                dpg.set_value(f"phys_contact_{name}_{side}", list(decimate(t, row + 0.8 * c, 400)))
            now = {k: float(h.window(name, f"ragdoll_{k}", end, 1)[0]) for k in ("residual_bw", "error_cm", "falls")}
            if not np.isfinite(now["error_cm"]):       # no ragdoll at this tick (before the first, or off)
                continue
            fallen = bool(h.window(name, "ragdoll_fallen", end, 1)[0] > 0.5)
            shown[name] = {**now, "fallen": fallen,
                           "mean_error_cm": float(np.nanmean(err)) if np.isfinite(err).any() else float("nan"),
                           "median_residual_bw": float(np.nanmedian(res)) if np.isfinite(res).any() else float("nan")}
        for tag in ("res", "err", "contact"):
            dpg.set_axis_limits(f"phys_{tag}_x", float(t[0]), 0.0)
        tops = [float(np.nanpercentile(h.window(nm, "ragdoll_residual_bw", end, n), 98)) for nm in shown
                if np.isfinite(h.window(nm, "ragdoll_residual_bw", end, n)).any()]
        dpg.set_axis_limits("phys_res_y", 0.0, min(max(tops + [1.5]) * 1.1, 5.0))
        etop = max([float(np.nanmax(h.window(nm, "ragdoll_error_cm", end, n))) for nm in shown
                    if np.isfinite(h.window(nm, "ragdoll_error_cm", end, n)).any()] + [10.0])
        dpg.set_axis_limits("phys_err_y", 0.0, min(etop * 1.1, 200.0))

        def line(name, v):
            res = "off" if not np.isfinite(v["residual_bw"]) else f"{v['residual_bw']:.2f} BW"
            state = "  FALLEN" if v["fallen"] else ""
            return f"{SHORT[name]}: residual {res}, error {v['error_cm']:.1f} cm, falls {int(v['falls'])}{state}"

        text = "   |   ".join(line(nm, v) for nm, v in shown.items()) if shown else \
            ("simulation off" if not settings.get("enabled", True) else "no tick yet")
        self.text.set("phys_numbers", text)
        self.last = {"status": "", "tick": end, "controllers": shown, "settings": dict(settings)}
