"""Latent traces: the learned controller's latent variables over the last seconds (heat map, one row
per dimension), beside the compressor's latent of the frames motion matching plays, and one chosen
dimension of both as curves."""
from __future__ import annotations

import numpy as np

from .common import COLORS, TextCache, View, window_tag

MAX_COLUMNS = 240


def heat_matrix(values: np.ndarray, max_columns: int = MAX_COLUMNS) -> tuple[np.ndarray, int]:
    """(T, L) series -> row-major (L, C) heat map values (one row per dimension, oldest column first),
    decimated to at most ``max_columns`` columns; NaN becomes 0. Returns (flat values, columns)."""
    v = np.asarray(values, np.float64)
    if v.ndim != 2 or v.shape[0] == 0:
        return np.zeros(1), 1
    step = max(1, int(np.ceil(v.shape[0] / max_columns)))
    v = v[::-1][::step][::-1]      # keep the newest column exactly
    v = np.nan_to_num(v, nan=0.0)
    return np.ascontiguousarray(v.T).ravel(), v.shape[0]


def latent_scale(values: np.ndarray, floor: float = 0.5) -> float:
    """A symmetric colour range covering the 98th percentile of |values| (at least ``floor``)."""
    v = np.abs(np.asarray(values, np.float64))
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 1.0
    return max(float(np.percentile(v, 98)), floor)


class LatentPanel:
    def __init__(self, dpg, studio):
        self.dpg = dpg
        self.studio = studio
        self.tag = window_tag("latent")
        self.text = TextCache(dpg)
        self.seconds = 5.0
        self.dim = 0
        self.n_latent = 32
        self.last = {}
        self._scale = {"lmm": 1.0, "mm": 1.0}

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        with dpg.window(tag=self.tag, label="Latent Traces", **window_kwargs):
            with dpg.group(horizontal=True):
                dpg.add_text("window")
                dpg.add_slider_float(tag="lat_seconds", default_value=self.seconds, min_value=1.0, max_value=20.0,
                                     width=110, format="%.0f s", callback=lambda s, a: setattr(self, "seconds", a))
                dpg.add_text("dim")
                dpg.add_slider_int(tag="lat_dim", default_value=0, min_value=0, max_value=self.n_latent - 1, width=90,
                                   callback=lambda s, a: setattr(self, "dim", int(a)))
                dpg.add_text("", tag="lat_status")
            for key, title in (("lmm", "LMM"), ("mm", "MM")):
                with dpg.plot(tag=f"lat_plot_{key}", height=66, width=-1, no_menus=True, no_mouse_pos=True,
                              no_box_select=True, no_title=True):
                    dpg.add_plot_axis(dpg.mvXAxis, tag=f"lat_x_{key}", no_tick_labels=key == "lmm")
                    with dpg.plot_axis(dpg.mvYAxis, tag=f"lat_y_{key}", label=title, no_tick_labels=True):
                        dpg.add_heat_series([0.0], 1, 1, tag=f"lat_heat_{key}", format="", scale_min=-1, scale_max=1,
                                            bounds_min=(-self.seconds, 0), bounds_max=(0, self.n_latent))
                dpg.bind_colormap(f"lat_plot_{key}", dpg.mvPlotColormap_RdBu)
            with dpg.plot(tag="lat_curve_plot", height=-1, width=-1, no_menus=True, no_mouse_pos=True):
                dpg.add_plot_legend(location=dpg.mvPlot_Location_North, horizontal=True, outside=True)
                dpg.add_plot_axis(dpg.mvXAxis, tag="lat_curve_x", label="seconds")
                with dpg.plot_axis(dpg.mvYAxis, tag="lat_curve_y", auto_fit=True):
                    dpg.add_line_series([0.0], [0.0], tag="lat_curve_lmm", label="LMM latent[0]")
                    dpg.add_line_series([0.0], [0.0], tag="lat_curve_mm", label="MM matched latent[0]")
        self.studio.theme_series("lat_curve_lmm", COLORS["lmm"], weight=2.0)
        self.studio.theme_series("lat_curve_mm", COLORS["mm"], weight=2.0)

    def update(self, view: View) -> None:
        dpg = self.dpg
        h = view.history
        dt = self.studio.session.dt
        n = max(int(self.seconds / dt), 2)
        end = view.tick_number
        t = (np.arange(n) - (n - 1)) * dt
        series = {}
        session = self.studio.session
        if h.has_series("lmm", "latent"):
            series["lmm"] = h.window("lmm", "latent", end, n)
        if h.has_series("mm", "matched_latent"):       # the controller reports it itself
            series["mm"] = h.window("mm", "matched_latent", end, n)
        elif h.has_series("mm", "matched_frame"):      # else look the frames up in the compressor table
            z = session.matched_latents(h.window("mm", "matched_frame", end, n))
            if z is not None:
                series["mm"] = z
        for key, v in series.items():  # each map's colour range follows its recent values smoothly
            if v.ndim == 2:
                self._scale[key] = 0.9 * self._scale[key] + 0.1 * latent_scale(v[-60:])
        for key in ("lmm", "mm"):
            v = series.get(key)
            tag = f"lat_heat_{key}"
            if v is None or v.ndim != 2:
                dpg.configure_item(tag, show=False)
                continue
            flat, cols = heat_matrix(v)
            rows = v.shape[1]
            sc = self._scale[key]
            dpg.configure_item(tag, show=True, rows=rows, cols=cols, scale_min=-sc, scale_max=sc,
                               bounds_min=(float(t[0]), 0.0), bounds_max=(0.0, float(rows)))
            dpg.configure_item(f"lat_y_{key}", label=f"{key.upper()} ±{sc:.1f}")
            dpg.set_value(tag, [flat])
            dpg.set_axis_limits(f"lat_x_{key}", float(t[0]), 0.0)
            dpg.set_axis_limits(f"lat_y_{key}", 0.0, float(rows))
        dim = self.dim
        for key, tag, label in (("lmm", "lat_curve_lmm", "LMM latent"), ("mm", "lat_curve_mm", "MM matched latent")):
            v = series.get(key)
            if v is None or v.ndim != 2 or dim >= v.shape[1]:
                dpg.set_value(tag, [t[-1:], np.zeros(1)])
            else:
                y = v[:, dim]
                ok = np.isfinite(y)
                dpg.set_value(tag, [t[ok], y[ok]])
            dpg.configure_item(tag, label=f"{label}[{dim}]")
        dpg.set_axis_limits("lat_curve_x", float(t[0]), 0.0)
        missing = [k for k in ("lmm", "mm") if k not in series]
        reasons = {"lmm": "LMM not running", "mm": session.latent_table_status or "no MM latents"}
        status = "; ".join(reasons[k] for k in missing)
        self.text.set("lat_status", status)
        self.last = {"end_tick": end, "columns": n,
                     "lmm_latest": series["lmm"][-1].tolist() if "lmm" in series and series["lmm"].ndim == 2 else None,
                     "mm_latest": series["mm"][-1].tolist() if "mm" in series and series["mm"].ndim == 2 else None,
                     "status": status}

    def state(self) -> dict:
        return dict(self.last)
