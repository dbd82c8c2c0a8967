"""Feature vector bars: the query beside the MM matched frame's features and the LMM projector's
output, dimension by dimension, in normalised units (weights included), grouped by channel with the
channel weights in the axis labels."""
from __future__ import annotations

import numpy as np

from .base import Panel, View
from .common import COLORS, QUERY_COLOR, SHORT, short_channel_name

BAR_WIDTH = 0.26


def bar_layout(features) -> dict:
    """x positions and labels of the grouped bar chart (pure, for tests).

    Dimension ``d`` sits at ``x = d + gap * channel(d)``, so channels are separated by a gap; each
    channel gets one tick label (short name and weight) at its centre and separators between them.
    """
    gap = 1.0
    xs, centres, separators, labels = [], [], [], []
    x = 0.0
    for i, (ch, s) in enumerate(zip(features.layout, features.slices)):
        n = s.stop - s.start
        dims = x + np.arange(n, dtype=np.float64)
        xs.append(dims)
        centres.append(float(dims.mean()))
        labels.append(f"{short_channel_name(ch.name)}\nw {float(features.weights[i]):.2f}")
        x = dims[-1] + 1.0 + gap
        if i < len(features.layout) - 1:
            separators.append(float(dims[-1] + 0.5 + gap / 2.0))
    return {"x": np.concatenate(xs), "centres": centres, "labels": labels, "separators": separators}


def bar_values(view: View) -> dict:
    """The series the panel plots: name -> (D,) normalised values or None (pure)."""
    q = view.snap()
    mm, lmm = view.snap_of("mm"), view.snap_of("lmm")
    return {
        "query": None if q is None else np.asarray(q.query, np.float64),
        "matched": None if mm is None else np.asarray(mm.matched_features, np.float64),
        "projected": None if lmm is None or lmm.projected_features is None
        else np.asarray(lmm.projected_features, np.float64),
    }


def _tiled_starts(features, n: int) -> list[int] | None:
    """The channels' start indices when they tile a vector of ``n`` values end to end (one ``reduceat``
    sums every channel), else None."""
    starts = [s.start for s in features.slices]
    if starts and all(s.stop == e for s, e in zip(features.slices, starts[1:] + [n])):
        return starts
    return None


def channel_errors(features, a, b) -> list[float]:
    """Per-channel squared distance between two normalised vectors (nan when either is missing)."""
    if a is None or b is None:
        return [float("nan")] * len(features.layout)
    d = np.asarray(a, np.float64) - np.asarray(b, np.float64)
    starts = _tiled_starts(features, len(d))
    if starts is not None:
        return np.add.reduceat(d * d, starts).tolist()     # the channels tile the vector: one call
    return [float(np.sum(d[s] ** 2)) for s in features.slices]


def total_error(features, a: np.ndarray, b: np.ndarray) -> float:
    """``np.sum(channel_errors(features, a, b))`` of two float64 vectors, without the per-channel list:
    the same sums (each channel's squares, then numpy's sum of them)."""
    d = a - b
    starts = _tiled_starts(features, len(d))
    if starts is None:
        return float(np.sum(channel_errors(features, a, b)))
    return float(np.sum(np.add.reduceat(d * d, starts)))


class FeaturesPanel(Panel):
    key = "features"
    commands = ()
    reads = ("inspected", "snap", "snap_of")
    _weights = None
    _bar_x = None      # bar x positions per shift (the layout's x never changes)

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        self.layout = bar_layout(self.ctx.engine.features)
        x = self.layout["x"]
        with self.window(window_kwargs):
            dpg.add_text("", tag="feat_summary")
            with dpg.plot(tag="feat_plot", height=-1, width=-1, no_menus=True, no_mouse_pos=True):
                dpg.add_plot_legend(location=dpg.mvPlot_Location_North, horizontal=True, outside=True)
                xa = dpg.add_plot_axis(dpg.mvXAxis, tag="feat_x", no_gridlines=True)
                dpg.set_axis_ticks(xa, tuple(zip(self.layout["labels"], self.layout["centres"])))
                dpg.set_axis_limits(xa, float(x[0]) - 1.0, float(x[-1]) + 1.0)
                with dpg.plot_axis(dpg.mvYAxis, tag="feat_y", label="normalised", auto_fit=True):
                    zeros = np.zeros_like(x)
                    dpg.add_bar_series(x - BAR_WIDTH, zeros, weight=BAR_WIDTH, label="query", tag="feat_query")
                    dpg.add_bar_series(x, zeros, weight=BAR_WIDTH, label="MM matched", tag="feat_matched")
                    dpg.add_bar_series(x + BAR_WIDTH, zeros, weight=BAR_WIDTH, label="LMM projected",
                                       tag="feat_projected")
                    dpg.add_inf_line_series(self.layout["separators"], tag="feat_sep")
        theme = self.ctx.theme
        theme.series("feat_query", QUERY_COLOR, bar=True)
        theme.series("feat_matched", COLORS["mm"], bar=True)
        theme.series("feat_projected", COLORS["lmm"], bar=True)
        theme.series("feat_sep", (0.45, 0.45, 0.5), weight=1.0)

    def prepare(self, view: View) -> dict:
        """The plotted vectors and each controller's distance from its own query to its answer (the
        projector answered LMM's query, the search MM's; None when there is none)."""
        features = self.ctx.engine.features
        vals = bar_values(view)
        mm, lmm = view.snap_of("mm"), view.snap_of("lmm")
        total_m = total_p = None
        if mm is not None and vals["matched"] is not None:
            total_m = total_error(features, np.asarray(mm.query, np.float64), vals["matched"])
        if lmm is not None and vals["projected"] is not None:
            total_p = total_error(features, np.asarray(lmm.query, np.float64), vals["projected"])
        return {"vals": vals, "total_m": total_m, "total_p": total_p}

    def update(self, view: View, prepared: dict | None = None) -> None:
        dpg = self.dpg
        features = self.ctx.engine.features
        weights = tuple(float(self.ctx.tuning.feature_weights.get(ch.name, w))
                        for ch, w in zip(features.layout, features.weights))
        if weights != self._weights:  # weights changed: relabel the channels
            self._weights = weights
            labels = [f"{short_channel_name(ch.name)}\nw {w:.2f}" for ch, w in zip(features.layout, weights)]
            dpg.set_axis_ticks("feat_x", tuple(zip(labels, self.layout["centres"])))
            self.layout["labels"] = labels
        p = prepared if prepared is not None else self.prepare(view)
        vals = p["vals"]
        x = self.layout["x"]
        if self._bar_x is None:
            self._bar_x = {shift: x + shift for shift in (-BAR_WIDTH, 0.0, BAR_WIDTH)}
            self._zeros = np.zeros_like(x)
        for key, tag, shift in (("query", "feat_query", -BAR_WIDTH), ("matched", "feat_matched", 0.0),
                                ("projected", "feat_projected", BAR_WIDTH)):
            v = vals[key]
            dpg.set_value(tag, [self._bar_x[shift], self._zeros if v is None else v])
        inspected = SHORT.get(view.inspected, view.inspected)
        self.text.configure("feat_query", label=f"query ({inspected})")
        total_m, total_p = p["total_m"], p["total_p"]
        summary = f"query of {inspected}"
        if total_m is not None:
            summary += f"   |   MM: |query - matched|^2 = {total_m:.3f}"
        if total_p is not None:
            summary += f"   |   LMM: |query - projected|^2 = {total_p:.3f}"
        self.text.set("feat_summary", summary)
        nan = float("nan")
        self.last = {"query": vals["query"], "matched": vals["matched"], "projected": vals["projected"],
                     "cost_matched": nan if total_m is None else total_m,
                     "cost_projected": nan if total_p is None else total_p}

    def state(self) -> dict:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.last.items()}
