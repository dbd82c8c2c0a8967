"""The "Nearest Neighbour vs Projector" panel: at each search of the learned controller, the exact nearest
database frame of the query and its cost beside the projector's output (its nearest frame) and its cost,
their feature distance, the agreement rate over time, and a cost timeline (MM best cost, LMM exact and
projected cost, searches and transitions marked). Database frames are named here (:func:`frame_label`)
for the candidates panel too (:mod:`.candidates`).
"""
from __future__ import annotations

import re

import numpy as np

from app.history import masks_agreement, search_masks

from .base import Panel, View
from .channel_costs import ChannelCostPlot
from .common import COLORS, GOOD, decimate, fmt_num, seconds_axis


def frame_label(db, frame: int) -> tuple[str, float]:
    """(clip name, seconds into the clip range) of a database frame."""
    if frame is None or frame < 0 or frame >= db.n_frames:
        return "-", float("nan")
    r = int(db.range_index(frame))
    r = min(r, db.n_ranges - 1)
    name = db.range_names[r] if r < len(db.range_names) else f"range {r}"
    name = re.sub(r"\[\d+:\d+\]", "", name).replace("_subject", " s").replace("multipleActions", "multiActions")
    name = name.replace(" mirrored", " (mirror)")
    if bool(db.range_mirrored[r]) and "mirror" not in name:
        name += " (mirror)"
    return name, (frame - int(db.range_starts[r])) / db.fps


def frame_tags(db, frame: int) -> str:
    """The tags of a database frame's range, comma separated ("" when it has none)."""
    if db is None or frame is None or not 0 <= frame < db.n_frames:
        return ""
    return ", ".join(db.tags_of(int(frame)))


def rolling_agreement(searched, nn, got, window: int, tolerance: int = 0) -> np.ndarray:
    """Per tick, the agreement rate of the searches in the preceding ``window`` ticks (nan before the
    first search)."""
    return rolling_rate(*search_masks(searched, nn, got, tolerance), window)


def rolling_rate(s: np.ndarray, agree: np.ndarray, window: int) -> np.ndarray:
    """:func:`rolling_agreement` of the masks of :func:`search_masks`."""
    n = _window_sums(s, window)
    a = _window_sums(agree, window)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, a / np.maximum(n, 1), np.nan)


def _window_sums(mask: np.ndarray, window: int) -> np.ndarray:
    """Per index i, how many of ``mask[max(i - window + 1, 0):i + 1]`` are set (differences of a running sum)."""
    c = np.cumsum(mask)
    out = c.copy()
    if window < len(c):     # a window longer than the series: every index sums from the start
        out[window:] -= c[:len(c) - window]
    return out


class SearchPanel(Panel):
    """Nearest neighbour vs projector, with the cost timeline; a second tab, the per-channel cost timeline
    (:mod:`.channel_costs`)."""
    key = "search"
    commands = ("scrub",)
    reads = ("history", "problems", "snap_of", "tick_number", "tick", "inspected")
    seconds = 10.0
    tolerance = 6
    view_name = "projector"          # the tab shown: "projector" or "channels"

    def __init__(self, ctx):
        super().__init__(ctx)
        self._labels: dict[int, tuple[str, str]] = {}
        engine = ctx.engine
        self.channel_plot = ChannelCostPlot(ctx.dpg, ctx.theme, engine.channel_names, engine.features_of, engine.dt,
                                            on_pick=lambda tick: self.ctx.actions.scrub(tick=tick))

    def show_view(self, name: str) -> None:
        """Show the tab ``name`` ("projector": nearest neighbour vs projector; "channels": channel costs)."""
        if name not in ("projector", "channels"):
            raise ValueError(f"no view {name!r} in the search panel (projector, channels)")
        self.view_name = name
        if self.dpg.get_value("search_tabs") != f"search_tab_{name}":
            self.dpg.set_value("search_tabs", f"search_tab_{name}")

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        with self.window(window_kwargs):
            # the tab bar's value is the shown tab's tag
            with dpg.tab_bar(tag="search_tabs", callback=lambda s, a: self.show_view(str(a)[len("search_tab_"):])):
                with dpg.tab(label="NN vs projector", tag="search_tab_projector"):
                    dpg.add_text("", tag="nn_status")
                    with dpg.table(header_row=True, borders_innerH=True, borders_outerH=True, borders_innerV=True,
                                   row_background=True, policy=dpg.mvTable_SizingStretchProp, tag="nn_table"):
                        dpg.add_table_column(label="", init_width_or_weight=0.55)
                        dpg.add_table_column(label="exact NN", init_width_or_weight=1.0)
                        dpg.add_table_column(label="LMM projector", init_width_or_weight=1.0)
                        dpg.add_table_column(label="MM search", init_width_or_weight=1.0)
                        for key, label in (("frame", "frame"), ("clip", "clip, time"), ("cost", "query cost")):
                            with dpg.table_row():
                                dpg.add_text(label)
                                for col in ("nn", "proj", "mm"):
                                    dpg.add_text("-", tag=f"nn_{col}_{key}")
                    with dpg.group(horizontal=True):
                        dpg.add_text("distance |proj - X[nn]|")
                        dpg.add_text("-", tag="nn_distance", color=(230, 230, 140))
                        dpg.add_text("  agreement")
                        dpg.add_text("-", tag="nn_agreement", color=(230, 230, 140))
                    with dpg.tooltip("nn_agreement"):
                        dpg.add_text("Share of the LMM searches in the window where the database frame nearest to the\n"
                                     "projector's output lies within the tolerance of the exact nearest neighbour.")
                    with dpg.plot(tag="cost_plot", height=-28, width=-1, no_menus=True, no_mouse_pos=True):
                        dpg.add_plot_legend(location=dpg.mvPlot_Location_North, horizontal=True, outside=True)
                        dpg.add_plot_axis(dpg.mvXAxis, tag="cost_x", label="seconds")
                        with dpg.plot_axis(dpg.mvYAxis, tag="cost_y", label="cost", auto_fit=True):
                            z = [0.0]
                            dpg.add_line_series(z, z, tag="cost_mm", label="MM best")
                            dpg.add_line_series(z, z, tag="cost_nn", label="LMM exact NN")
                            dpg.add_line_series(z, z, tag="cost_proj", label="LMM projected")
                            dpg.add_scatter_series(z, z, tag="cost_transitions", label="MM transitions")
                        with dpg.plot_axis(dpg.mvYAxis2, tag="cost_y2", label="agreement", opposite=True):
                            dpg.add_line_series(z, z, tag="cost_agree", label="agreement")
                        dpg.set_axis_limits("cost_y2", 0.0, 1.05)
                    with dpg.group(horizontal=True):
                        dpg.add_text("tolerance")
                        dpg.add_slider_int(tag="nn_tolerance", default_value=self.tolerance, min_value=0, max_value=60,
                                           width=110, format="%d frames", callback=lambda s, a: setattr(self, "tolerance", int(a)))
                        dpg.add_text("window")
                        dpg.add_slider_float(tag="nn_seconds", default_value=self.seconds, min_value=2.0, max_value=20.0,
                                             width=90, format="%.0f s", callback=lambda s, a: setattr(self, "seconds", a))
                with dpg.tab(label="channel costs", tag="search_tab_channels"):
                    self.channel_plot.build()
        theme = self.ctx.theme
        theme.series("cost_mm", COLORS["mm"], weight=2.0)
        theme.series("cost_nn", (0.95, 0.95, 0.95), weight=1.5)
        theme.series("cost_proj", COLORS["lmm"], weight=2.0)
        theme.series("cost_transitions", COLORS["mm"], marker=True)
        theme.series("cost_agree", GOOD, weight=1.5)

    def _label(self, frame: int) -> tuple[str, str]:
        """The frame and clip cells of a database frame (a frame's clip never changes: the cache is
        read anywhere, written by ``_keep_label`` on the GUI thread)."""
        cells = self._labels.get(frame)
        if cells is None:
            db = self.ctx.engine.db
            clip, tc = frame_label(db, frame)
            tags = frame_tags(db, frame)
            cells = ("-" if frame < 0 else str(frame) + (f" [{tags}]" if tags else ""),
                     "-" if frame < 0 else f"{clip[:22]} {tc:5.2f}s")
        return cells

    def _keep_label(self, frame: int, cells: tuple[str, str]) -> None:
        if frame not in self._labels:
            if len(self._labels) > 4096:
                self._labels.clear()
            self._labels[frame] = cells

    def prepare_key(self, view: View) -> tuple:
        return (self.seconds, self.tolerance, self.view_name)

    def prepare(self, view: View) -> dict:
        """The table's numbers, the agreement and the cost plot's series of the window ending at the
        view's tick."""
        db = self.ctx.engine.db
        h = view.history
        dt = self.ctx.engine.dt
        n = max(int(self.seconds / dt), 2)
        end = view.tick_number
        t = seconds_axis(n, dt)
        lmm, mm = view.snap_of("lmm"), view.snap_of("mm")
        shown = {}
        out = {"shown": shown, "end": end, "t": t, "lmm": lmm is not None,
               "channels": self.channel_plot.prepare(view, self.view_name == "channels")}
        if lmm is not None:
            # each series is gathered once: the table, the agreement and its curve share them
            searched = h.window("lmm", "searched", end, n)
            nn = h.window("lmm", "nn_frame", end, n)
            projected = h.window("lmm", "projected_frame", end, n)
            nn_frame = int(lmm.nn_frame)
            proj = projected[np.isfinite(projected)]
            proj_frame = int(proj[-1]) if len(proj) else -1
            shown["nn"] = (nn_frame, float(lmm.nn_cost))
            shown["proj"] = (proj_frame, float(lmm.projected_cost))
            dist = float("nan")
            if lmm.projected_features is not None and 0 <= nn_frame < db.n_frames:
                features = self.ctx.engine.features_of("lmm")
                dist = float(np.linalg.norm(np.asarray(lmm.projected_features) - features.normalized[nn_frame]))
            # which ticks searched and agreed, once for the rate and its curve
            masks = search_masks(searched, nn, projected, self.tolerance)
            rate, k = masks_agreement(*masks)
            ag = rolling_rate(*masks, int(2.0 / dt))
            ok = np.isfinite(ag)
            out["agree_curve"] = list(decimate(t[ok], ag[ok], 300)) if ok.any() else [t[-1:], np.zeros(1)]
        else:
            dist, rate, k = float("nan"), float("nan"), 0
        if mm is not None:
            shown["mm"] = (int(mm.matched_frame), float(mm.best_cost))
        out.update(dist=dist, rate=rate, k=k)
        out["cells"] = {col: self._label(shown.get(col, (-1,))[0]) for col in ("nn", "proj", "mm")}
        curves = {}
        best_cost = None
        for name, field, tag in (("mm", "best_cost", "cost_mm"), ("lmm", "nn_cost", "cost_nn"),
                                 ("lmm", "projected_cost", "cost_proj")):
            y = h.window(name, field, end, n)
            if tag == "cost_mm":
                best_cost = y
            ok = np.isfinite(y)
            held = int(np.count_nonzero(ok))
            if held == len(y):     # every tick has a cost (the usual case): no masked copies to make
                curves[tag] = list(decimate(t, y, 300))
            elif held:
                curves[tag] = list(decimate(t[ok], y[ok], 300))
            else:
                curves[tag] = (False, [t[-1:], np.zeros(1)])
                continue
            curves[tag] = (True, curves[tag])
        out["curves"] = curves
        tr = h.window("mm", "transitioned", end, n) > 0.5
        sel = tr & np.isfinite(best_cost)
        out["transitions"] = ([t[sel], best_cost[sel]] if sel.any() else [t[-1:], np.zeros(1)])
        return out

    def update(self, view: View, prepared: dict | None = None) -> None:
        dpg = self.dpg
        cache = self.text
        p = prepared if prepared is not None else self.prepare(view)
        shown, t, end = p["shown"], p["t"], p["end"]
        dist, rate, k = p["dist"], p["rate"], p["k"]
        if p["lmm"]:
            agree = "-" if k == 0 else f"{100 * rate:.0f}% of {k} searches"
            cache.set("nn_status", "LMM projector vs exact nearest neighbour of the same query")
        else:
            agree = "-"
            cache.set("nn_status", view.problems.get("lmm") or "LMM is not running")
        for col in ("nn", "proj", "mm"):
            frame, cost = shown.get(col, (-1, float("nan")))
            frame_cell, clip_cell = p["cells"][col]
            self._keep_label(frame, p["cells"][col])
            cache.set(f"nn_{col}_frame", frame_cell)
            cache.set(f"nn_{col}_clip", clip_cell)
            cache.set(f"nn_{col}_cost", fmt_num(cost))
        cache.set("nn_distance", fmt_num(dist))
        cache.set("nn_agreement", agree)
        for tag, (any_ok, curve) in p["curves"].items():
            dpg.set_value(tag, curve)
            cache.configure(tag, show=any_ok)
        dpg.set_value("cost_transitions", p["transitions"])
        if p["lmm"]:
            dpg.set_value("cost_agree", p["agree_curve"])
        cache.configure("cost_agree", show=p["lmm"])
        cache.axis_limits("cost_x", float(t[0]), 0.0)
        self.channel_plot.update(view, p["channels"], self.view_name == "channels")
        self.last = {"tick": end, "nn_frame": shown.get("nn", (-1,))[0], "nn_cost": shown.get("nn", (0, None))[1],
                     "projected_frame": shown.get("proj", (-1,))[0],
                     "projected_cost": shown.get("proj", (0, None))[1],
                     "mm_frame": shown.get("mm", (-1,))[0], "mm_cost": shown.get("mm", (0, None))[1],
                     "distance": dist, "agreement": rate, "searches": k}

    def state(self) -> dict:
        out = {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in self.last.items()}
        return dict(out, view=self.view_name, channel_costs=self.channel_plot.last)
