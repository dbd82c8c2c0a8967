"""The "Search Candidates" panel: the ranked top-K candidates of the inspected controller's last search
with per-channel costs (green = cheapest to red = dearest in each column), sortable by any column;
clicking a row previews that database frame (the Database panel and a ghost in the 3D view). While the ticks
run, the rows hold still as long as the pointer is over one of them, so that the row clicked is the row seen."""
from __future__ import annotations

import numpy as np

from .base import Panel, View
from .common import SHORT, cost_color, fmt_num, short_channel_name
from .search import frame_label, frame_tags

MAX_ROWS = 64
#: put before the status while the rows are held (see :meth:`CandidatesPanel._holds_rows`): at the start
#: of the line, which a narrow panel does not cut
HOLD_HINT = "rows held under the pointer | "
#: frames the rows stay held after the pointer was last over one: the hover drops for a frame after a
#: click (seen once in ten runs of 30 real clicks), and the rows must not move then
HOLD_GRACE_FRAMES = 2


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


def what_if_fields(channel_names, tuning) -> list[str]:
    """The scratch tuning's editable entries: the search's weights and biases (``field.entry`` for a per-name
    field)."""
    return (["transition_cost", "exclude_current_window_frames"] + [f"feature_weights.{n}" for n in channel_names]
            + [f"tag_bias.{t}" for t in tuning.tag_bias])


def split_field(entry: str) -> tuple[str, str | None]:
    """``feature_weights.hip_velocity`` -> (``feature_weights``, ``hip_velocity``); a plain field: (it, None)."""
    field, _, channel = entry.partition(".")
    return field, channel or None


class CandidatesPanel(Panel):
    """Ranked candidates of the inspected controller's last search."""
    key = "candidates"
    commands = ("preview_database_frame", "why_not", "what_if", "branch_here", "continuing_pose")
    reads = ("frame", "inspected", "mode", "paused", "snap", "tick_number")

    def __init__(self, ctx):
        super().__init__(ctx)
        self.sort_key = "total"
        self.descending = False
        self._shown_for = None
        self._highlighted: dict = {}     # (row, column) -> the colour dearpygui has for the cell (None: none)
        self.rows: list[dict] = []
        self._rows_on_screen: list[dict] = []     # the rows of the picture a click was made on (see _on_click)
        self._held_status: str | None = None      # the status shown while the rows are held (None: not held)
        self._hovered_frame = -HOLD_GRACE_FRAMES - 1  # the last studio frame that found the pointer over a row
        self._hover_age: int | None = None        # frames since then, at the last update (for the state dump)
        self.columns: list[str] = []
        self.why_frame: int | None = None     # the frame asked about (refreshed when the shown tick changes)
        self.why_text = ""
        self.continuing: dict | None = None   # the continuing pose's explanation at the shown search (or None)
        self._reviewing = False               # a reopened session was shown at the last tick change
        self.what_if: dict | None = None      # the re-ranked search shown instead of the tick's ({tick, result, ..})
        self._asked_tick = -1

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        names = self.ctx.engine.channel_names
        self.columns = (["rank", "frame", "clip", "tags", "t", "total", "bias"]
                        + [f"ch{i}" for i in range(len(names))])
        labels = ["#", "frame", "clip", "tags", "t (s)", "total", "bias"] + [short_channel_name(n) for n in names]
        with self.window(window_kwargs):
            dpg.add_text("", tag="cand_status")
            self._build_questions()
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

    def _build_questions(self) -> None:
        """Why not a typed frame; what if: one scratch weight, tag bias or cost at a time; branch here."""
        dpg, actions = self.dpg, self.ctx.actions
        # folded by default: the ranked table is what the panel is for, and it keeps its rows in small layouts
        with dpg.collapsing_header(label="why not / what if", tag="cand_questions", default_open=False):
            with dpg.group(horizontal=True):
                dpg.add_input_int(label="why not frame", tag="cand_why_frame", width=90, on_enter=True,
                                  callback=lambda s, v: actions.why_not(int(v)))
                dpg.add_button(label="branch here (what if)", callback=lambda: actions.branch_here(scratch=True))
            with dpg.group(horizontal=True):
                dpg.add_combo(what_if_fields(self.ctx.engine.channel_names, self.ctx.tuning), tag="cand_wi_field",
                              default_value="transition_cost", width=200)
                dpg.add_input_float(tag="cand_wi_value", width=80, step=0, format="%.3f")
                dpg.add_button(label="what if", callback=lambda: self.ask_what_if(dpg.get_value("cand_wi_field"),
                                                                                   dpg.get_value("cand_wi_value")))
                dpg.add_button(label="clear what if", callback=lambda: actions.what_if(clear=True))
        dpg.add_text("", tag="cand_why", wrap=0, show=False)     # shown while it holds an answer

    def ask_what_if(self, entry: str, value) -> None:
        """One more scratch edit (``entry`` of :func:`what_if_fields`) and the tick's search re-ranked."""
        field, channel = split_field(entry)
        self.ctx.actions.what_if(field=field, value=value, channel=channel)

    def _on_sort(self, sender, sort_specs):
        if not sort_specs:
            return
        col, direction = sort_specs[0]
        key = self.dpg.get_item_user_data(col)
        self.sort_key = key or "total"
        self.descending = direction < 0
        self._shown_for = None  # redraw

    def _on_click(self, sender, value, r):
        """A click runs two updates after the picture it was made on was set up (dearpygui takes it in
        the next frame's drawing, or the one after when it came during a drawing; its callback runs in
        the frame after), and the table re-sorts at every search: the frame previewed is that of the row
        drawn last, which is the row the user saw while the rows are held (:meth:`_holds_rows`)."""
        self.dpg.set_value(sender, False)      # a click previews; the row does not stay selected
        if 0 <= r < len(self._rows_on_screen):
            self.ctx.actions.preview_database_frame(int(self._rows_on_screen[r]["frame"]))

    def click_row(self, r: int) -> None:
        """Preview the database frame of the shown row ``r`` (0 = top)."""
        if 0 <= r < len(self.rows):
            self.ctx.actions.preview_database_frame(int(self.rows[r]["frame"]))

    def set_sort(self, key: str, descending: bool = False) -> None:
        self.sort_key, self.descending = key, descending
        self._shown_for = None

    def prepare_key(self, view: View) -> tuple:
        return (self.sort_key, self.descending, id(self.what_if))   # a what-if re-ranks: prepare again

    def prepare(self, view: View) -> dict | None:
        """The sorted rows of the inspected controller's candidates and their colour fractions. Reading
        the candidates runs motion matching's ranked search when the tick's search left it for the first
        reader (see :class:`lmm.mm.MotionMatchingController`): on the tick worker, not the GUI thread."""
        snap = view.snap()
        if snap is None:
            return None
        cands = self._candidates(view, snap)
        rows = sort_rows(candidate_rows(cands, self.ctx.engine.db), self.sort_key, self.descending)
        fractions = {k: column_fractions(rows, k) for k in self.columns if k == "total" or k.startswith("ch")}
        return {"candidates": cands, "rows": rows, "fractions": fractions}

    def update(self, view: View, prepared: dict | None = None) -> None:
        dpg = self.dpg
        self._rows_on_screen = self.rows      # drawn by the last frame, on screen until this one is
        snap = view.snap()
        if view.tick_number != self._asked_tick:        # the asked frame and the what if follow the shown tick
            self._asked_tick = view.tick_number
            self._follow_tick(view)
        cands = None if snap is None else self._candidates(view, snap)
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
        if cands is not snap.candidates:
            edits = ", ".join(f"{f}{'.' + c if c else ''}={v}" for f, v, c in self.what_if["changes"])
            status += f"\nWHAT IF (scratch tuning: {edits or 'no edits'}): this tick's search re-ranked, rows marked w"
        c = self.continuing
        if c is not None and not c["excluded"] and cands is not None and len(cands.frames):
            kept = "kept" if c["frame"] == int(cands.frames[0]) else "beaten"
            status += (f"\ncontinuing pose {c['frame']}: total {c['total']:.3f} = features {c['feature_cost']:.3f}"
                       f" + bias {c['bias']:.3f} (no transition cost); {kept}")
        self._show_why()
        if self._holds_rows(view, key):        # the status stays that of the rows shown, and as many lines
            if self._held_status is None:
                self._held_status = HOLD_HINT + self.text.get("cand_status", "")
            self.text.set("cand_status", self._held_status)
            return
        self._held_status = None
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
                    txt = ("w" if cands is not snap.candidates else "") + txt
                    if self.text.get(f"cand_{r}_{k}") != txt:
                        self.text.values[f"cand_{r}_{k}"] = txt
                        dpg.configure_item(f"cand_{r}_{k}", label=txt)
                    continue
                self.text.set(f"cand_{r}_{k}", txt)
                if k in fractions:
                    self._highlight(r, c, cost_color(fractions[k][r]))
            self._highlight(r, 1, (60, 110, 200, 170) if row["frame"] == snap.matched_frame else None)

    def _holds_rows(self, view: View, key: tuple) -> bool:
        """Whether to keep the rows as shown: while the ticks run and the pointer is over a row (or was,
        up to ``HOLD_GRACE_FRAMES`` frames ago). A click is taken one or two frames after the picture it
        was made on, and dearpygui cannot say which; live, the table re-sorts at every search, so a row
        under the pointer must not change for a click to preview the row the user saw. A sort, a what-if
        or another inspected controller (another key but the candidates') redraws at once."""
        if any(self.dpg.is_item_hovered(f"cand_{r}_rank") for r in range(min(len(self.rows), MAX_ROWS))):
            self._hovered_frame = view.frame
        age = self._hover_age = view.frame - self._hovered_frame
        if view.paused or self._shown_for is None or key[1:] != self._shown_for[1:]:
            return False
        return 0 <= age <= HOLD_GRACE_FRAMES

    def _follow_tick(self, view: View) -> None:
        """Ask again at a new shown tick of a reopened session, paused (only it can be asked: live, the
        answers are dropped; playing, they stay those of the tick they name: each costs a few ms)."""
        actions, reviewing = self.ctx.actions, view.mode == "SESSION"
        self.continuing = actions.continuing_pose() if reviewing and view.paused else None
        left, self._reviewing = self._reviewing and not reviewing, reviewing
        if left:                                          # the session's answers go with it
            self.show_why_not(None, [])
            self.show_what_if(None)
        if not reviewing or not view.paused:              # playing: the answers name the tick they are of
            return
        if self.why_frame is not None:
            actions.why_not(self.why_frame)
        if self.what_if is not None:
            actions.what_if()

    def _candidates(self, view: View, snap):
        """The what-if re-ranking when one is kept for the shown tick and controller, else the tick's own."""
        w = self.what_if
        if w is not None and w["tick"] == view.tick_number and w["controller"] == view.inspected:
            return w["result"]
        return snap.candidates

    def show_why_not(self, frame: int | None, lines: list[str]) -> None:
        """What the why-not command found for ``frame`` (None: nothing asked)."""
        self.why_frame, self.why_text = frame, "\n".join(lines)
        self._show_why()

    def _show_why(self) -> None:
        self.text.set("cand_why", self.why_text)
        self.text.configure("cand_why", show=bool(self.why_text))

    def show_what_if(self, what_if: dict | None) -> None:
        """The what-if re-ranking to show in the table (None: the tick's own search again)."""
        self.what_if = what_if
        self._shown_for = None

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
        return {"sort": self.sort_key, "descending": self.descending, "why_not": self.why_text,
                "held": self._held_status is not None, "hover_age": self._hover_age,
                "status": self.text.get("cand_status"),
                "what_if": None if self.what_if is None else {"tick": self.what_if["tick"],
                                                              "changes": self.what_if["changes"]},
                "rows": [{k: v for k, v in r.items()} for r in self.rows]}
