"""Latent traces: the learned controller's latent variables over the last seconds (heat map, one row
per dimension), beside the compressor's latent of the frames motion matching plays, and one chosen
dimension of both as curves."""
from __future__ import annotations

import functools

import numpy as np

from .base import Panel, View
from .common import COLORS, seconds_axis

COLUMNS = 200
GAP = 2.0       # rows of space between the two maps
MISSING_RGBA = (0.2, 0.2, 0.22, 1.0)   # a NaN cell: dark grey


def diverging_lut(n: int = 256) -> np.ndarray:
    """(n, 4) float32 RGBA: blue (negative) -> near white (0) -> red (positive)."""
    t = np.linspace(-1.0, 1.0, n)[:, None]
    neg = np.array([0.16, 0.36, 0.78])
    mid = np.array([0.93, 0.93, 0.93])
    pos = np.array([0.80, 0.22, 0.18])
    a = np.abs(t) ** 0.8
    rgb = np.where(t < 0, mid + (neg - mid) * a, mid + (pos - mid) * a)
    return np.concatenate([rgb, np.ones((n, 1))], axis=1).astype(np.float32)


def heat_image(values: np.ndarray, scale: float, lut: np.ndarray, columns: int = COLUMNS,
               out: np.ndarray | None = None) -> np.ndarray:
    """(T, L) series -> (L, columns, 4) RGBA image, one row per dimension (image row 0 = dimension 0; a plot
    image shows it at the bottom), oldest tick left, newest right; ``[-scale, scale]`` spans the colour map;
    NaN is dark grey."""
    v = np.asarray(values, np.float64)
    T, L = v.shape
    idx = _column_ticks(T, columns)
    k = v.take(idx, axis=0).T                                                             # (L, columns)
    bad = ~np.isfinite(k)
    # in place, the same operations as ((k / scale) + 1) * 0.5 * (n - 1) clipped to the table
    np.divide(k, max(scale, 1e-9), out=k)
    k += 1.0
    k *= 0.5
    k *= len(lut) - 1
    np.clip(k, 0, len(lut) - 1, out=k)
    if bad.any():
        # the NaN colour as one more row of the table: one gather colours every cell (setting the
        # bad cells of the (L, columns, 4) image afterwards costs more than the rest of the map)
        lut = np.concatenate([lut, np.asarray([MISSING_RGBA], lut.dtype)])
        k[bad] = len(lut) - 1
    if out is None:
        out = np.empty((L, columns, lut.shape[1]), lut.dtype)
    # the indices in the image's own row order (k is a transposed view) and mode="clip" (they are in
    # the table already): take then writes straight into ``out``, about half the time of a buffered,
    # strided gather
    np.take(lut, k.astype(np.intp, order="C"), axis=0, out=out, mode="clip")
    return out


@functools.lru_cache(maxsize=16)
def _column_ticks(T: int, columns: int) -> np.ndarray:
    """Which of ``T`` ticks each of ``columns`` image columns shows (the newest always kept)."""
    return np.clip(np.round(np.linspace(0, T - 1, columns)).astype(np.int64), 0, T - 1)


def latent_scale(values: np.ndarray, floor: float = 0.5) -> float:
    """A symmetric colour range covering the 98th percentile of |values| (at least ``floor``)."""
    v = np.abs(np.asarray(values, np.float64))
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 1.0
    return max(float(np.percentile(v, 98)), floor)


class LatentPanel(Panel):
    key = "latent"
    commands = ()
    reads = ("frame", "history", "latent_status", "problems", "tick_number")

    def __init__(self, ctx):
        super().__init__(ctx)
        self.seconds = 5.0
        self.dim = 0
        self.n_latent = ctx.engine.latent_dims
        self._scale = {"lmm": 1.0, "mm": 1.0}
        self.lut = diverging_lut()
        self._label_shown = {}

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        self.images = {}
        for key in ("lmm", "mm"):
            self.images[key] = np.zeros((self.n_latent, COLUMNS, 4), np.float32)
            self.images[key][..., 3] = 1.0
            dpg.add_raw_texture(COLUMNS, self.n_latent, self.images[key], format=dpg.mvFormat_Float_rgba,
                                tag=f"lat_tex_{key}", parent="texture_registry")
        with self.window(window_kwargs):
            with dpg.group(horizontal=True):
                dpg.add_text("window")
                dpg.add_slider_float(tag="lat_seconds", default_value=self.seconds, min_value=1.0, max_value=20.0,
                                     width=110, format="%.0f s", callback=lambda s, a: setattr(self, "seconds", a))
                dpg.add_text("dim")
                dpg.add_slider_int(tag="lat_dim", default_value=0, min_value=0, max_value=self.n_latent - 1, width=90,
                                   callback=lambda s, a: setattr(self, "dim", int(a)))
            # why a map is empty, on its own line and wrapped: it can be long ("computing ...")
            dpg.add_text("", tag="lat_status", wrap=0, color=(170, 170, 180))
            # both maps in one plot (LMM above, MM below), each a single textured quad: far cheaper to
            # draw than thousands of heat-map cells, and one plot frame instead of two
            L = self.n_latent
            with dpg.plot(tag="lat_plot", height=116, width=-1, no_menus=True, no_mouse_pos=True,
                          no_box_select=True, no_title=True):
                dpg.add_plot_axis(dpg.mvXAxis, tag="lat_x")
                with dpg.plot_axis(dpg.mvYAxis, tag="lat_y", no_gridlines=True):
                    for key in ("lmm", "mm"):
                        lo, hi = self._rows(key)
                        dpg.add_image_series(f"lat_tex_{key}", (-self.seconds, lo), (0, hi),
                                             tag=f"lat_heat_{key}", show=False)
                dpg.set_axis_limits("lat_y", 0.0, 2 * L + GAP)
                dpg.set_axis_ticks("lat_y", (("MM", L / 2), ("LMM", L + GAP + L / 2)))
            with dpg.plot(tag="lat_curve_plot", height=-1, width=-1, no_menus=True, no_mouse_pos=True):
                dpg.add_plot_legend(location=dpg.mvPlot_Location_North, horizontal=True, outside=True)
                dpg.add_plot_axis(dpg.mvXAxis, tag="lat_curve_x", label="seconds")
                with dpg.plot_axis(dpg.mvYAxis, tag="lat_curve_y", auto_fit=True):
                    dpg.add_line_series([0.0], [0.0], tag="lat_curve_lmm", label="LMM latent[0]")
                    dpg.add_line_series([0.0], [0.0], tag="lat_curve_mm", label="MM matched latent[0]")
        self.ctx.theme.series("lat_curve_lmm", COLORS["lmm"], weight=2.0)
        self.ctx.theme.series("lat_curve_mm", COLORS["mm"], weight=2.0)

    def _rows(self, key: str) -> tuple[float, float]:
        """y range of a map: MM at the bottom, LMM above it (dimension 0 is the bottom row of each)."""
        L = float(self.n_latent)
        return (L + GAP, 2 * L + GAP) if key == "lmm" else (0.0, L)

    prepare_uses_frame = True     # the colour ranges ease every sixth frame

    def prepare_key(self, view: View) -> tuple:
        return (self.seconds, self.dim, tuple(self._scale.items()))

    def prepare(self, view: View) -> dict:
        """The windows of both latents, their colour ranges after this frame's smoothing step, their heat
        images and the chosen dimension's curves."""
        h = view.history
        dt = self.ctx.engine.dt
        n = max(int(self.seconds / dt), 2)
        end = view.tick_number
        t = seconds_axis(n, dt)
        series = {}
        for key, field in (("lmm", "latent"), ("mm", "matched_latent")):   # the controllers report them
            if h.has_series(key, field):
                series[key] = h.window(key, field, end, n)
        scale = dict(self._scale)
        for key, v in series.items():  # each map's colour range follows its recent values smoothly
            if v.ndim == 2 and view.frame % 6 == 0:
                scale[key] = 0.7 * scale[key] + 0.3 * latent_scale(v[-60:])
        images, curves = {}, {}
        dim = self.dim
        for key in ("lmm", "mm"):
            v = series.get(key)
            ok_map = v is not None and v.ndim == 2 and v.shape[1] == self.n_latent
            images[key] = heat_image(v, scale[key], self.lut, COLUMNS) if ok_map else None
            if v is None or v.ndim != 2 or dim >= v.shape[1]:
                curves[key] = [t[-1:], np.zeros(1)]
            else:
                y = v[:, dim]
                ok = np.isfinite(y)
                curves[key] = [t, np.ascontiguousarray(y)] if ok.all() else [t[ok], y[ok]]
        return {"n": n, "t": t, "series": series, "scale": scale, "images": images, "curves": curves}

    def update(self, view: View, prepared: dict | None = None) -> None:
        dpg = self.dpg
        p = prepared if prepared is not None else self.prepare(view)
        n, t, series = p["n"], p["t"], p["series"]
        end = view.tick_number
        self._scale.update(p["scale"])
        cache = self.text
        for key in ("lmm", "mm"):
            tag = f"lat_heat_{key}"
            image = p["images"][key]
            if image is None:
                cache.configure(tag, show=False)
                continue
            np.copyto(self.images[key], image)   # in place: the texture shows it
            lo, hi = self._rows(key)
            cache.configure(tag, show=True, bounds_min=(float(t[0]), lo), bounds_max=(0.0, hi))
        labels = tuple(f"{k.upper()} ±{self._scale[k]:.1f}" for k in ("mm", "lmm"))
        if labels != self._label_shown.get("ticks"):
            self._label_shown["ticks"] = labels
            L = self.n_latent
            dpg.set_axis_ticks("lat_y", ((labels[0], L / 2), (labels[1], L + GAP + L / 2)))
        cache.axis_limits("lat_x", float(t[0]), 0.0)
        dim = self.dim
        for key, tag, label in (("lmm", "lat_curve_lmm", "LMM latent"), ("mm", "lat_curve_mm", "MM matched latent")):
            dpg.set_value(tag, p["curves"][key])
            cache.configure(tag, label=f"{label}[{dim}]")
        cache.axis_limits("lat_curve_x", float(t[0]), 0.0)
        missing = [k for k in ("lmm", "mm") if k not in series]
        reasons = {"lmm": "LMM: " + (view.problems.get("lmm") or "not running"),
                   "mm": "MM: " + (view.latent_status or "no matched latents")}
        status = "; ".join(reasons[k] for k in missing)
        self.text.set("lat_status", status)
        self.last = {"end_tick": end, "columns": n,
                     "lmm_latest": series["lmm"][-1].tolist() if "lmm" in series and series["lmm"].ndim == 2 else None,
                     "mm_latest": series["mm"][-1].tolist() if "mm" in series and series["mm"].ndim == 2 else None,
                     "status": status}

