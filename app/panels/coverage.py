"""Coverage: where the database holds motion, and where the characters ask for motion it lacks.

* the 2D map of the database's feature space (:mod:`lmm.coverage`: PCA of the normalised, weighted
  feature vectors; every frame drawn into one image, coloured by tag or root speed, with each class's
  median position marked), with each character's
  query of the displayed tick (its colour, a large dot) and a short trail of its queries before it;
* the root speed x turning-rate heat map of the database (seconds per cell; dark red: none) with each
  character's asked-for speed and turning rate marked;
* the histogram of one feature channel's dimensions with each character's query values on it;
* the distance from each query to the nearest database frame, in search cost units (for motion
  matching, the nearest frame it may pick: frames of excluded tags are drawn dim and left out).

Everything follows the displayed tick (live or picked on the timeline). The coverage itself is computed
once, as a background job (:mod:`app.jobs`), the first time the window is shown (the panel says so
meanwhile); the map's picture is drawn by a job too.
"""
from __future__ import annotations

import numpy as np

from lmm.coverage import Coverage, DataDistance, build_coverage, first_trajectory_dims
from lmm.reporting import PALETTE, category_centres, heat_colors, map_bounds, map_categories, map_image

from ..jobs import Jobs
from .base import Panel, View
from .common import COLORS, SHORT, fmt_num, short_channel_name
from .coverage_query import QueryReport, distance_for

MAP_TEXELS = 200            # the map image's side: every database frame is drawn into it
TRAIL_S = 2.0               # seconds of queries behind the current one
TRAIL_POINTS = 40
MAX_CATEGORIES = 8          # map colour classes (beyond that, the last one holds the rest)
HEAT_UPSCALE = 8            # texels per heat map cell side
DIM_COLORS = PALETTE[:MAX_CATEGORIES - 2]   # histogram dimensions: not the characters' orange and blue
MAX_DIMS = 6                # most dimensions in one channel (trajectory channels: 3 offsets x 2)
CONTROLLERS = ("mm", "lmm")
MODES = ("tag", "speed")


def heat_texture(cov: Coverage, upscale: int = HEAT_UPSCALE) -> np.ndarray:
    """(S * upscale, T * upscale, 4) float32 RGBA of the speed x turn heat map, fastest row first (a
    plot image shows the texture's first row at the top of its bounds); each cell is ``upscale``
    texels a side so that the texture's linear filtering blurs only the cells' borders."""
    seconds = cov.heatmap.seconds[::-1]
    rgb = heat_colors(seconds / max(float(seconds.max()), 1e-9)).astype(np.float32) / 255.0
    rgba = np.concatenate([rgb, np.ones(rgb.shape[:-1] + (1,), np.float32)], axis=-1)
    return np.ascontiguousarray(np.repeat(np.repeat(rgba, upscale, axis=0), upscale, axis=1))


def percentile_in(hist_edges: np.ndarray, hist_counts: np.ndarray, value: float) -> float:
    """Share (0-100) of the database's values below ``value``, from one dimension's histogram."""
    if not np.isfinite(value):
        return float("nan")
    cum = np.concatenate([[0.0], np.cumsum(hist_counts, dtype=np.float64)])
    return float(100.0 * np.interp(value, hist_edges, cum) / max(cum[-1], 1.0))


class CoveragePanel(Panel):
    key = "coverage"
    reads = ("history", "snap_of", "tick", "tick_number")

    def __init__(self, ctx, jobs: Jobs | None = None):
        super().__init__(ctx)
        self.jobs = jobs if jobs is not None else Jobs()   # the coverage and the map's picture, off the GUI thread
        self.mode = "tag"
        self.channel = 0
        self.trail = True
        self.cov: Coverage | None = None
        self._distance: dict[str, tuple[np.ndarray, DataDistance]] = {}
        self._shown_for = None
        self._map_wanted = None       # (mode, excluded tags) the map is asked for
        self._map_shown = None        # (mode, excluded tags) the map shows
        self._map_job = None          # the map being drawn (a Job, see _want_map)
        self.map_error = ""
        self._searchable = None       # (N,) bool: the frames those leave to motion matching (None: every one)
        self._job = None              # the coverage being worked out (a Job, see _start_coverage)
        self.error = ""

    # -- build ---------------------------------------------------------------------------------
    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        features = self.ctx.engine.features
        with self.window(window_kwargs):
            dpg.add_text("", tag="cov_status", wrap=0)
            with dpg.group(horizontal=True):
                dpg.add_text("colour by")
                dpg.add_radio_button(MODES, tag="cov_mode", horizontal=True, default_value=self.mode,
                                     callback=lambda s, a: self.set_mode(a))
                dpg.add_checkbox(label="trail", tag="cov_trail", default_value=self.trail,
                                 callback=lambda s, a: setattr(self, "trail", bool(a)))
            with dpg.table(header_row=False, policy=dpg.mvTable_SizingStretchProp, tag="cov_top",
                           borders_innerV=False):
                dpg.add_table_column(init_width_or_weight=1.15)
                dpg.add_table_column(init_width_or_weight=1.0)
                with dpg.table_row():
                    with dpg.plot(tag="cov_map", height=220, width=-1, no_menus=True, equal_aspects=False):
                        dpg.add_plot_legend(location=dpg.mvPlot_Location_NorthEast, outside=False)
                        dpg.add_plot_axis(dpg.mvXAxis, tag="cov_map_x", label="PC1", auto_fit=True)
                        with dpg.plot_axis(dpg.mvYAxis, tag="cov_map_y", label="PC2", auto_fit=True):
                            z = [0.0]
                            for i in range(MAX_CATEGORIES):   # each class's median position (and the legend)
                                dpg.add_scatter_series(z, z, tag=f"cov_cat_{i}", label=f"{i}", show=False)
                            for name in CONTROLLERS:
                                dpg.add_line_series(z, z, tag=f"cov_trail_{name}", show=False)
                                dpg.add_scatter_series(z, z, tag=f"cov_q_{name}", label=SHORT[name], show=False)
                    with dpg.plot(tag="cov_heat", height=220, width=-1, no_menus=True, no_mouse_pos=True):
                        dpg.add_plot_axis(dpg.mvXAxis, tag="cov_heat_x", label="turning rate (deg/s)")
                        with dpg.plot_axis(dpg.mvYAxis, tag="cov_heat_y", label="speed (m/s)"):
                            for name in CONTROLLERS:
                                dpg.add_scatter_series([0.0], [0.0], tag=f"cov_hq_{name}", label=SHORT[name],
                                                       show=False)
            with dpg.group(horizontal=True):
                dpg.add_text("channel")
                dpg.add_combo([ch.name for ch in features.layout], tag="cov_channel", width=180,
                              default_value=features.layout[0].name,
                              callback=lambda s, a: self.set_channel(a))
            dpg.add_text("", tag="cov_hist_status", color=(190, 190, 200), wrap=0)
            with dpg.plot(tag="cov_hist", height=-1, width=-1, no_menus=True, no_mouse_pos=True):
                dpg.add_plot_legend(location=dpg.mvPlot_Location_NorthEast, horizontal=True, outside=False)
                dpg.add_plot_axis(dpg.mvXAxis, tag="cov_hist_x", auto_fit=True)
                with dpg.plot_axis(dpg.mvYAxis, tag="cov_hist_y", label="frames", auto_fit=True):
                    for d in range(MAX_DIMS):
                        dpg.add_line_series([0.0], [0.0], tag=f"cov_hist_{d}", label=f"{d}", show=False)
                    for name in CONTROLLERS:
                        dpg.add_inf_line_series([0.0], tag=f"cov_hq_line_{name}", label=f"{SHORT[name]} query",
                                                show=False)
        theme = self.ctx.theme
        for i in range(MAX_CATEGORIES):
            theme.series(f"cov_cat_{i}", PALETTE[i % len(PALETTE)], marker=True, marker_size=6.0)
        for d in range(MAX_DIMS):
            theme.series(f"cov_hist_{d}", DIM_COLORS[d % len(DIM_COLORS)], weight=1.5)
        for name in CONTROLLERS:
            theme.series(f"cov_trail_{name}", COLORS[name], weight=2.0)
            theme.series(f"cov_q_{name}", COLORS[name], marker=True, marker_size=7.0)
            theme.series(f"cov_hq_{name}", COLORS[name], marker=True, marker_size=7.0)
            theme.series(f"cov_hq_line_{name}", COLORS[name], weight=2.0)

    # -- controls ------------------------------------------------------------------------------
    def set_mode(self, mode: str) -> None:
        """Colour the map by ``tag`` or ``speed`` (the radio buttons, or a script)."""
        self.mode = mode if mode in MODES else "tag"
        self.dpg.set_value("cov_mode", self.mode)
        self._shown_for = None

    def set_channel(self, name: str) -> None:
        """Show the histograms of the feature channel ``name`` (the combo, or a script)."""
        names = self.ctx.engine.features.names
        self.channel = names.index(name) if name in names else 0
        self.dpg.set_value("cov_channel", names[self.channel])
        self._shown_for = None

    # -- the coverage (computed once) ----------------------------------------------------------
    def _start_coverage(self) -> None:
        """Work out the coverage and the nearest-frame indexes as a job (about 1.5 s for 0.5 M frames here,
        0.2 s for the default data), so the studio keeps drawing meanwhile; :meth:`_ensure_coverage` shows
        the result (the map's picture is drawn by a job too, see :meth:`_want_map`)."""
        engine = self.ctx.engine

        def work(job):
            try:
                cov = build_coverage(engine.db, engine.features)
                horizon = first_trajectory_dims(engine.features.layout)[2]
                # the running controllers' nearest-frame indexes too (0.17 s each for 0.5 M frames)
                distance = {n: distance_for(engine.features_of(n))
                            for n in CONTROLLERS if n in engine.controller_names()}
            except Exception as e:  # noqa: BLE001 - a layout without trajectory channels: said, studio runs on
                raise RuntimeError(f"no coverage: {e}") from e
            return cov, horizon, distance

        def failed(line):
            self._job = None
            self.error = line
            self.text.set("cov_status", self.error)

        self._job = self.jobs.submit("coverage", work, on_done=self._took_coverage, on_error=failed)
        self.text.set("cov_status", f"working out the coverage of {engine.db.n_frames:,} frames ...")

    def _ensure_coverage(self) -> bool:
        """The coverage is shown (True); else its job is started (the first call), or its outcome taken
        once it finished (a later one)."""
        if self.cov is None and not self.error and self._job is None:
            self._start_coverage()
            return False
        self.jobs.poll()
        return self.cov is not None

    def _took_coverage(self, result) -> None:
        """The coverage job's result: the heat map and the map's textures and axes (GUI thread)."""
        self._job = None
        self.cov, self.horizon, distance = result
        self._distance.update(distance)
        dpg = self.dpg
        cov = self.cov
        tex = heat_texture(cov)
        rows, cols = tex.shape[:2]
        dpg.add_static_texture(cols, rows, tex.ravel(), tag="cov_heat_tex", parent="texture_registry")
        se, te = cov.heatmap.speed_edges_m_s, cov.heatmap.turn_edges_deg_s
        dpg.add_image_series("cov_heat_tex", (float(te[0]), float(se[0])), (float(te[-1]), float(se[-1])),
                             tag="cov_heat_img", parent="cov_heat_y", before=f"cov_hq_{CONTROLLERS[0]}")
        dpg.set_axis_limits("cov_heat_x", float(te[0]), float(te[-1]))
        dpg.set_axis_limits("cov_heat_y", float(se[0]), float(se[-1]))
        lo, hi = map_bounds(cov)
        self.map_tex = np.zeros((MAP_TEXELS, MAP_TEXELS, 4), np.float32)
        dpg.add_raw_texture(MAP_TEXELS, MAP_TEXELS, self.map_tex, format=dpg.mvFormat_Float_rgba, tag="cov_map_tex",
                            parent="texture_registry")
        dpg.add_image_series("cov_map_tex", (float(lo[0]), float(lo[1])), (float(hi[0]), float(hi[1])),
                             tag="cov_map_img", parent="cov_map_y", before="cov_cat_0")
        ratio = cov.pca.variance_ratio
        dpg.configure_item("cov_map_x", label=f"PC1 ({100 * ratio[0]:.0f}%)")
        dpg.configure_item("cov_map_y", label=f"PC2 ({100 * ratio[1]:.0f}%)")

    def _data_distance(self, name: str) -> DataDistance:
        """The nearest-frame search over the controller's features as they are normalised now (weights
        change with the sliders), rebuilt when they change."""
        features = self.ctx.engine.features_of(name)
        have = self._distance.get(name)
        if have is None or have[0] is not features.normalized:   # the array itself: a weight change replaces it
            have = self._distance[name] = distance_for(features)
        distance = have[1]
        # motion matching's nearest frame among those it may pick; the learned controller's networks do
        # not know the exclusions, so its nearest frame is any
        searchable = self._searchable if name == "mm" else None
        distance.mask = distance.every if searchable is None else searchable
        return distance

    # -- every frame ---------------------------------------------------------------------------
    def _layout_heights(self) -> None:
        dpg = self.dpg
        _, h = dpg.get_item_rect_size(self.tag)
        top = int(max(140, (h - 120) * 0.58))
        if top != self.text.get("__top_height"):
            self.text.values["__top_height"] = top
            dpg.configure_item("cov_map", height=top)
            dpg.configure_item("cov_heat", height=top)

    def _excluded_tags(self) -> tuple[str, ...]:
        """The database's tags the tuning excludes from the search now (motion matching's)."""
        return self.ctx.tuning.excluded_tags(self.ctx.engine.db.tag_names)

    def _want_map(self, mode: str, excluded_tags: tuple[str, ...]) -> None:
        """The map is asked for in ``mode`` with ``excluded_tags`` dimmed: the frames motion matching may
        pick (its nearest-frame distance) change at once; the picture is drawn by a job (0.2 s for 0.5 M
        frames) while the old one stays, and shown when it is done (:meth:`_show_map`); a job asked for
        before it is cancelled."""
        excluded = self.ctx.engine.db.tag_mask(excluded_tags) if excluded_tags else None
        if excluded is not None and excluded.all():   # the search ignores such an exclusion (one-line note)
            excluded = None
        self._searchable = None if excluded is None else ~excluded
        self.last["excluded_tags"] = list(excluded_tags) if excluded is not None else []
        self.last["excluded_frames"] = int(excluded.sum()) if excluded is not None else 0
        key = (mode, excluded_tags)
        self._map_wanted = key
        cov = self.cov

        def work(job):
            labels, cat = map_categories(cov, mode, MAX_CATEGORIES)
            image = map_image(cov, cat, MAP_TEXELS, MAP_TEXELS, excluded)
            if excluded is not None:              # each class's marker at its frames still searched
                cat = np.where(excluded, -1, cat)
            return key, image, labels, int(len(cat)), category_centres(cov, cat, len(labels))

        def failed(line):                         # said on the status line, the old map stays
            self.map_error = f"the map could not be drawn: {line}"
            self._map_job = None

        if self._map_job is not None:
            self._map_job.cancel()
        self._map_job = self.jobs.submit("coverage-map", work, on_done=self._show_map, on_error=failed)

    def _show_map(self, result) -> None:
        """Show the map a job drew (the one last asked for: earlier ones are cancelled)."""
        self._map_job = None
        key, image, labels, frames, centres = result
        self.map_error = ""
        dpg = self.dpg
        self.map_tex[...] = image              # in place: the texture shows it
        for i in range(MAX_CATEGORIES):
            tag = f"cov_cat_{i}"
            if i < len(labels) and np.isfinite(centres[i]).all():
                dpg.set_value(tag, [[float(centres[i, 0])], [float(centres[i, 1])]])
                dpg.configure_item(tag, label=labels[i], show=True)
            else:
                dpg.configure_item(tag, show=False)
        self._map_shown = key
        self.last["categories"] = labels
        self.last["frames_drawn"] = frames
        self.last["map"] = {"mode": key[0], "excluded_tags": list(key[1])}

    def update(self, view: View) -> None:
        if not self._ensure_coverage():
            return
        dpg = self.dpg
        self._layout_heights()
        excluded_tags = self._excluded_tags()
        if self._map_wanted != (self.mode, excluded_tags):
            self._want_map(self.mode, excluded_tags)
        shown_before = self._map_shown
        self.jobs.poll()
        pending = self._map_shown != self._map_wanted
        key = (view.tick_number, self.mode, self.channel, self.trail, tuple(view.tick.snapshots) if view.tick else (),
               excluded_tags, self._map_shown != shown_before, pending, self.map_error)
        if key == self._shown_for:
            return
        self._shown_for = key
        cov = self.cov
        engine = self.ctx.engine
        n_trail = max(int(TRAIL_S / engine.dt), 1)
        reports: dict[str, QueryReport] = {}
        for name in CONTROLLERS:
            snap = view.snap_of(name)
            if snap is None:
                continue
            trail = view.history.window(name, "query", view.tick_number, n_trail)
            if trail.ndim == 2:
                trail = trail[np.linspace(0, len(trail) - 1, min(TRAIL_POINTS, len(trail))).round().astype(int)]
            reports[name] = QueryReport(cov, self._data_distance(name), engine.features_of(name), snap, trail,
                                        self.horizon, engine.db.fps)
        # the map and the heat map: each character's query
        for name in CONTROLLERS:
            r = reports.get(name)
            dpg.configure_item(f"cov_q_{name}", show=r is not None)
            dpg.configure_item(f"cov_trail_{name}", show=r is not None and self.trail)
            dpg.configure_item(f"cov_hq_{name}", show=bool(r is not None and np.isfinite(r.speed)))
            if r is None:
                continue
            dpg.set_value(f"cov_q_{name}", [[float(r.xy[0])], [float(r.xy[1])]])
            dpg.set_value(f"cov_trail_{name}", [r.trail[:, 0].tolist(), r.trail[:, 1].tolist()])
            if np.isfinite(r.speed):
                se, te = cov.heatmap.speed_edges_m_s, cov.heatmap.turn_edges_deg_s
                dpg.set_value(f"cov_hq_{name}", [[float(np.clip(r.turn, te[0], te[-1]))],
                                                 [float(np.clip(r.speed, se[0], se[-1]))]])
        # the status: distance to the data and the heat map cell of each query
        lines = []
        for name in CONTROLLERS:
            r = reports.get(name)
            if r is None:
                continue
            tags = engine.db.tags_of(r.nearest_frame)
            lines.append(f"{SHORT[name]}: nearest frame {r.nearest_frame}" + (f" [{', '.join(tags)}]" if tags else "")
                         + f", cost {fmt_num(r.cost)} | {fmt_num(r.speed, 2)} m/s, {fmt_num(r.turn, 0)} deg/s: "
                         + f"{fmt_num(r.cell_seconds, 1)} s of data there")
        if self.last.get("excluded_tags"):
            lines.append(f"dark grey on the map: {self.last['excluded_frames']} frames of excluded tags "
                         f"({', '.join(self.last['excluded_tags'])}), which motion matching does not pick")
        if self.map_error:
            lines.append(self.map_error)
        elif pending:
            lines.append(f"drawing the map of {cov.n_frames:,} frames ...")
        self.text.set("cov_status", "\n".join(lines) if lines else "no query yet")
        # the chosen channel's histogram with the query values
        hist = cov.histograms[self.channel]
        s = engine.features.slices[self.channel]
        for d in range(MAX_DIMS):
            tag = f"cov_hist_{d}"
            if d < len(hist.dims):
                centres = (hist.edges[d, :-1] + hist.edges[d, 1:]) / 2
                dpg.set_value(tag, [centres, hist.counts[d].astype(np.float64)])
                dpg.configure_item(tag, label=hist.dims[d], show=True)
            else:
                dpg.configure_item(tag, show=False)
        percentiles = {}
        for name in CONTROLLERS:
            r = reports.get(name)
            tag = f"cov_hq_line_{name}"
            dpg.configure_item(tag, show=r is not None)
            if r is None:
                continue
            values = r.raw[s]
            dpg.set_value(tag, [values.tolist()])
            percentiles[name] = [percentile_in(hist.edges[d], hist.counts[d], float(v)) for d, v in enumerate(values)]
        unit = f" ({hist.unit})" if hist.unit else ""
        parts = [f"{SHORT[n]} " + " ".join(f"{lab} {p:.0f}%" for lab, p in zip(hist.dims, ps))
                 for n, ps in percentiles.items()]
        self.text.set("cov_hist_status",
                      f"{short_channel_name(hist.name)}{unit}; query percentile: " + "; ".join(parts))
        dpg.configure_item("cov_hist_x", label=f"{hist.name}{unit}")
        self.last.update({"tick": view.tick_number, "mode": self.mode, "channel": hist.name,
                          "variance_ratio": cov.pca.variance_ratio.tolist(),
                          "queries": {n: r.to_dict() for n, r in reports.items()},
                          "percentiles": percentiles, "error": self.error, "map_pending": pending,
                          "map_error": self.map_error})

    def state(self) -> dict:
        return dict(self.last)
