"""Search panels.

* "Nearest Neighbour vs Projector": at each search of the learned controller, the exact nearest
  database frame of the query and its cost beside the projector's output (its nearest frame) and its
  cost, their feature distance, the agreement rate over time, and a cost timeline (MM best cost, LMM
  exact and projected cost, searches and transitions marked).
* "Search Candidates": the ranked top-K candidates of the inspected controller with per-channel
  costs (green = cheapest to red = dearest in each column), sortable by any column; clicking a row
  previews that database frame (the Database panel and a ghost in the 3D view).
"""
from __future__ import annotations

import re

import numpy as np

from app.history import masks_agreement, search_masks

from .base import Panel, View
from .common import COLORS, GOOD, SHORT, cost_color, decimate, fmt_num, seconds_axis, short_channel_name

MAX_ROWS = 64


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


def candidate_rows(candidates, db=None) -> list[dict]:
    """One dict per ranked candidate (pure, for tests): rank, frame, clip, tags, t, total, bias, channels."""
    rows = []
    if candidates is None:
        return rows
    frames = np.asarray(candidates.frames)
    for i in range(len(frames)):
        clip, t = frame_label(db, int(frames[i])) if db is not None else ("-", float("nan"))
        rows.append({"rank": i + 1, "frame": int(frames[i]), "clip": clip, "tags": frame_tags(db, int(frames[i])),
                     "t": t,
                     "total": float(candidates.costs[i]), "bias": float(candidates.bias[i]),
                     "channels": [float(c) for c in np.asarray(candidates.channel_costs[i])]})
    return rows


def sort_rows(rows: list[dict], key: str, descending: bool = False) -> list[dict]:
    """Sort candidate rows by a column key (``rank``, ``frame``, ``clip``, ``t``, ``total``, ``bias``
    or ``ch<i>``); NaNs last."""
    def value(r):
        if key.startswith("ch"):
            v = r["channels"][int(key[2:])]
        else:
            v = r[key]
        if isinstance(v, str):
            return (0, v)
        return (1 if not np.isfinite(v) else 0, v)
    out = sorted(rows, key=value, reverse=descending)
    if descending:  # keep NaNs last
        out = [r for r in out if value(r)[0] == 0] + [r for r in out if value(r)[0] == 1]
    return out


def column_fractions(rows: list[dict], key: str, digits: int = 3) -> list[float]:
    """Each row's value of a cost column placed in the column's min..max as [0, 1], for colouring.

    Values are compared as shown (rounded to ``digits``): values that read the same get the same
    colour, and a column whose values all read the same is all 0 (green); a missing value is 1.
    """
    vals = np.array([r[key] if not key.startswith("ch") else r["channels"][int(key[2:])] for r in rows], float)
    if vals.size == 0:
        return []
    shown = np.round(vals, digits)
    finite = shown[np.isfinite(shown)]
    if finite.size == 0:
        return [0.5] * len(rows)
    lo, hi = float(finite.min()), float(finite.max())
    if hi - lo < 0.5 * 10.0 ** -digits:
        return [0.0 if np.isfinite(v) else 1.0 for v in shown]
    return [float((v - lo) / (hi - lo)) if np.isfinite(v) else 1.0 for v in shown]


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
    """Nearest neighbour vs projector, with the cost timeline."""
    key = "search"
    seconds = 10.0
    tolerance = 6

    def __init__(self, ctx):
        super().__init__(ctx)
        self._labels: dict[int, tuple[str, str]] = {}

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        with self.window(window_kwargs):
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
        return (self.seconds, self.tolerance)

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
        out = {"shown": shown, "end": end, "t": t, "lmm": lmm is not None}
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
        self.last = {"tick": end, "nn_frame": shown.get("nn", (-1,))[0], "nn_cost": shown.get("nn", (0, None))[1],
                     "projected_frame": shown.get("proj", (-1,))[0],
                     "projected_cost": shown.get("proj", (0, None))[1],
                     "mm_frame": shown.get("mm", (-1,))[0], "mm_cost": shown.get("mm", (0, None))[1],
                     "distance": dist, "agreement": rate, "searches": k}

    def state(self) -> dict:
        return {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in self.last.items()}


class CandidatesPanel(Panel):
    """Ranked candidates of the inspected controller's last search."""
    key = "candidates"

    def __init__(self, ctx):
        super().__init__(ctx)
        self.sort_key = "total"
        self.descending = False
        self._shown_for = None
        self._highlighted: dict = {}     # (row, column) -> the colour dearpygui has for the cell (None: none)
        self.rows: list[dict] = []
        self.columns: list[str] = []

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        names = self.ctx.engine.channel_names
        self.columns = (["rank", "frame", "clip", "tags", "t", "total", "bias"]
                        + [f"ch{i}" for i in range(len(names))])
        labels = ["#", "frame", "clip", "tags", "t (s)", "total", "bias"] + [short_channel_name(n) for n in names]
        with self.window(window_kwargs):
            dpg.add_text("", tag="cand_status")
            with dpg.table(tag="cand_table", header_row=True, sortable=True, callback=self._on_sort,
                           borders_innerV=True, borders_outerH=True, borders_outerV=True, resizable=True,
                           policy=dpg.mvTable_SizingFixedFit, scrollY=True, scrollX=True, freeze_rows=1,
                           height=-1):
                widths = {"rank": 18, "frame": 50, "clip": 150, "tags": 90, "t": 40, "total": 46, "bias": 40}
                for i, (key, label) in enumerate(zip(self.columns, labels)):
                    dpg.add_table_column(label=label, tag=f"cand_col_{key}", user_data=key,
                                         default_sort=(key == "total"), prefer_sort_ascending=True,
                                         width_fixed=True, init_width_or_weight=widths.get(key, 64))
                for r in range(MAX_ROWS):
                    with dpg.table_row(tag=f"cand_row_{r}", show=r < 8):
                        for key in self.columns:
                            if key == "rank":   # the whole row is clickable: preview its frame
                                dpg.add_selectable(label="", tag=f"cand_{r}_{key}", span_columns=True,
                                                   callback=self._on_click, user_data=r)
                            else:
                                dpg.add_text("", tag=f"cand_{r}_{key}")

    def _on_sort(self, sender, sort_specs):
        if not sort_specs:
            return
        col, direction = sort_specs[0]
        key = self.dpg.get_item_user_data(col)
        self.sort_key = key or "total"
        self.descending = direction < 0
        self._shown_for = None  # redraw

    def _on_click(self, sender, value, r):
        self.dpg.set_value(sender, False)      # a click previews; the row does not stay selected
        self.click_row(r)

    def click_row(self, r: int) -> None:
        """Preview the database frame of the shown row ``r`` (0 = top)."""
        if 0 <= r < len(self.rows):
            self.ctx.actions.preview_database_frame(int(self.rows[r]["frame"]))

    def set_sort(self, key: str, descending: bool = False) -> None:
        self.sort_key, self.descending = key, descending
        self._shown_for = None

    def prepare_key(self, view: View) -> tuple:
        return (self.sort_key, self.descending)

    def prepare(self, view: View) -> dict | None:
        """The sorted rows of the inspected controller's candidates and their colour fractions. Reading
        the candidates runs motion matching's ranked search when the tick's search left it for the first
        reader (see :class:`lmm.mm.MotionMatchingController`): on the tick worker, not the GUI thread."""
        snap = view.snap()
        if snap is None:
            return None
        cands = snap.candidates
        rows = sort_rows(candidate_rows(cands, self.ctx.engine.db), self.sort_key, self.descending)
        fractions = {k: column_fractions(rows, k) for k in self.columns if k == "total" or k.startswith("ch")}
        return {"candidates": cands, "rows": rows, "fractions": fractions}

    def update(self, view: View, prepared: dict | None = None) -> None:
        dpg = self.dpg
        snap = view.snap()
        cands = None if snap is None else snap.candidates
        key = (id(cands), self.sort_key, self.descending, view.inspected)
        if snap is None:
            self.text.set("cand_status", "no search yet")
            return
        name = SHORT.get(view.inspected, view.inspected)
        searched = "searched this tick" if snap.searched else "last search"
        forced = " (forced)" if snap.forced_search else ""
        tags = frame_tags(self.ctx.engine.db, snap.matched_frame)
        status = (f"{name}: {searched}{forced}, best frame {snap.matched_frame}"
                  + (f" [{tags}]" if tags else "") + f", cost {fmt_num(snap.best_cost)}")
        if snap.search_note:
            status += f"\n{snap.search_note}"
        self.text.set("cand_status", status)
        if key == self._shown_for:
            return
        self._shown_for = key
        if prepared is None or prepared["candidates"] is not cands:
            prepared = self.prepare(view)
        rows, fractions = prepared["rows"], prepared["fractions"]
        self.rows = rows
        for r in range(MAX_ROWS):
            show = r < len(rows)
            self.text.configure(f"cand_row_{r}", show=show)
            if not show:
                continue
            row = rows[r]
            for c, k in enumerate(self.columns):
                if k.startswith("ch"):
                    v = row["channels"][int(k[2:])]
                    txt = f"{v:.3f}"
                elif k == "clip":
                    txt = row["clip"][:24]
                elif k == "tags":
                    txt = row["tags"][:20]
                elif k == "t":
                    txt = f"{row['t']:.2f}"
                elif k in ("total", "bias"):
                    txt = f"{row[k]:.3f}"
                else:
                    txt = str(row[k])
                if k == "rank":
                    if self.text.get(f"cand_{r}_{k}") != txt:
                        self.text.values[f"cand_{r}_{k}"] = txt
                        dpg.configure_item(f"cand_{r}_{k}", label=txt)
                    continue
                self.text.set(f"cand_{r}_{k}", txt)
                if k in fractions:
                    self._highlight(r, c, cost_color(fractions[k][r]))
            self._highlight(r, 1, (60, 110, 200, 170) if row["frame"] == snap.matched_frame else None)

    def _highlight(self, row: int, column: int, color) -> None:
        """Colour one cell of the table (None: none), telling dearpygui only of a change (a call costs
        microseconds; a new search rewrote some fifty cells' colours, most of them the same)."""
        lit = self._highlighted
        if lit.get((row, column)) == color:
            return
        lit[(row, column)] = color
        if color is None:
            self.dpg.unhighlight_table_cell("cand_table", row, column)
        else:
            self.dpg.highlight_table_cell("cand_table", row, column, color)

    def state(self) -> dict:
        return {"sort": self.sort_key, "descending": self.descending,
                "rows": [{k: v for k, v in r.items()} for r in self.rows]}
