"""Database browser: every take and range of the motion database (file, frames in the file's own
numbering, tags, duration, mirrored or not). Selecting a range plays it as a preview ghost in the 3D
view (play/pause, loop, scrub) with its own future trajectory and pose features drawn, and its feature
vector beside the displayed query (the inspected character's, at the picked tick while scrubbing);
clicking a row in Search Candidates previews that frame here. "Copy manifest range" puts the selection
on the clipboard as the manifest's ``{"range": [a, b], "tags": [...]}`` in the file's frames.
"""
from __future__ import annotations

import json
from pathlib import PurePosixPath

import numpy as np

from lmm import quat
from lmm.data.ranges import RangeInfo, RangeSelectionError, database_ranges, manifest_range, range_of_frame
from lmm.errors import InputError

from .base import Panel, PreviewPose, View
from .common import QUERY_COLOR, SHORT, fmt_num
from .features import BAR_WIDTH, bar_layout
from .viewport_scene import feature_markers

PREVIEW_COLOR = (0.50, 0.95, 0.55)
TABLE_HEIGHT_PX = 230


def database_preview(db, features, frame: int, label: str, color=PREVIEW_COLOR) -> PreviewPose:
    """The preview ghost of database frame ``frame`` (pure, for tests): its global pose in the frame of
    its simulation bone, the future trajectory and the pose features of its feature vector."""
    rot, pos = db.global_transforms(slice(int(frame), int(frame) + 1))
    root_pos, root_rot = pos[0, 0], rot[0, 0]
    local = quat.inv_mul_vec(root_rot[None], pos[0] - root_pos[None])
    m = feature_markers(features, features.normalized[int(frame)], np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), {})
    return PreviewPose(label=label, positions=local, parents=np.asarray(db.parents), names=tuple(db.names),
                       trajectory=m["traj"], directions=m["traj_dirs"], points=m["points"], color=color)


def take_name(file: str) -> str:
    """A short name of a take for narrow tables: ``lafan1/walk1_subject5.bvh.gz`` -> ``walk1 s5``."""
    stem = PurePosixPath(str(file)).name.split(".")[0]
    return stem.replace("_subject", " s").replace("multipleActions", "multiActions")


def range_rows(ranges: list[RangeInfo]) -> list[dict]:
    """One table row per range (pure): file, frames, tags, seconds, mirrored."""
    return [{"index": r.index, "file": r.file, "take": take_name(r.file),
             "frames": f"{r.source_start}:{r.source_stop}", "tags": ", ".join(r.tags),
             "seconds": round(r.seconds, 3), "mirrored": r.mirrored} for r in ranges]


class DatabasePanel(Panel):
    key = "database"
    commands = ("show_error", "set_preview", "why_not")
    reads = ("frame", "inspected", "snap", "tick_number")

    def __init__(self, ctx):
        super().__init__(ctx)
        db = ctx.engine.db
        self.ranges = database_ranges(db, ctx.engine.manifest)
        self.rows = range_rows(self.ranges)
        self.selected: RangeInfo | None = None
        self.frame = -1                        # the previewed database frame (-1: none)
        self.origin = ""                       # "range" or "candidate"
        self.playing = False
        self.loop = True
        self.selection = (0, 0)                # file frames [from, to) of the selected range
        self.copied = ""
        self._shown = None                     # (frame, origin) the preview ghost shows
        self._last_frame_counter = None
        self._scroll_to = None                 # table row to bring into view

    # -- items --------------------------------------------------------------------------------
    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        takes = len({r.file for r in self.ranges})
        seconds = sum(r.seconds for r in self.ranges)
        self.layout = bar_layout(self.ctx.engine.features)
        x = self.layout["x"]
        with self.window(window_kwargs):
            dpg.add_text(f"{self.ctx.engine.db.name}: {takes} takes, {len(self.ranges)} ranges, "
                         f"{seconds:.0f} s at {self.ctx.engine.db.fps:g} fps; frames are the files' own",
                         tag="db_summary", wrap=0)
            with dpg.table(tag="db_table", header_row=True, borders_innerV=True, borders_outerH=True,
                           resizable=True, policy=dpg.mvTable_SizingStretchProp, scrollY=True, freeze_rows=1,
                           clipper=True,   # only the rows in view are laid out (manifests may have thousands)
                           height=TABLE_HEIGHT_PX, row_background=True):
                for key, label, w in (("take", "take", 1.25), ("frames", "frames", 0.85), ("tags", "tags", 1.3),
                                      ("seconds", "s", 0.4), ("mirrored", "mirror", 0.6)):
                    dpg.add_table_column(label=label, init_width_or_weight=w)
                for i, row in enumerate(self.rows):
                    with dpg.table_row():
                        dpg.add_selectable(label=row["take"], tag=f"db_row_{i}", span_columns=True,
                                           callback=self._on_row, user_data=i)
                        dpg.add_text(row["frames"])
                        dpg.add_text(row["tags"])
                        dpg.add_text(f"{row['seconds']:.1f}")
                        dpg.add_text("yes" if row["mirrored"] else "")
            dpg.add_text("select a range (or click a Search Candidates row) to preview it", tag="db_status",
                         wrap=0)
            with dpg.group(horizontal=True):
                dpg.add_button(label="Play", tag="db_play", width=60, callback=lambda: self.set_playing(not self.playing))
                dpg.add_checkbox(label="Loop", tag="db_loop", default_value=self.loop,
                                 callback=lambda s, a: setattr(self, "loop", bool(a)))
                dpg.add_slider_int(tag="db_scrub", width=-1, min_value=0, max_value=1, format="file frame %d",
                                   callback=lambda s, a: self.scrub_to_source(int(a)))
            with dpg.group(horizontal=True):
                dpg.add_text("selection")
                dpg.add_input_int(tag="db_from", width=70, step=0, callback=self._on_selection_field)
                dpg.add_text(":")
                dpg.add_input_int(tag="db_to", width=70, step=0, callback=self._on_selection_field)
                dpg.add_button(label="In", tag="db_in", callback=lambda: self.mark("in"))
                dpg.add_button(label="Out", tag="db_out", callback=lambda: self.mark("out"))
            with dpg.group(horizontal=True):
                dpg.add_button(label="Copy manifest range", tag="db_copy", callback=lambda: self.copy_range())
                dpg.add_button(label="Why not this frame?", tag="db_why_not", callback=lambda: self.why_not())
            with dpg.tooltip("db_copy"):
                dpg.add_text("Copies {\"range\": [from, to], \"tags\": [...]} in the file's own frames (to is\n"
                             "exclusive), ready to paste into the file's 'ranges' of a manifest.\n"
                             "In / Out set the selection's ends at the previewed frame.")
            dpg.add_text("", tag="db_copied", wrap=0, color=(170, 220, 170))
            dpg.add_text("", tag="db_cost")
            # horizontal bars: the channel names fit a tall narrow panel (first channel at the top)
            labels = [lab.replace("\n", " ") for lab in self.layout["labels"]]
            with dpg.plot(tag="db_plot", height=-1, width=-1, no_menus=True, no_mouse_pos=True):
                dpg.add_plot_legend(location=dpg.mvPlot_Location_North, horizontal=True, outside=True)
                dpg.add_plot_axis(dpg.mvXAxis, tag="db_x", label="normalised", auto_fit=True)
                with dpg.plot_axis(dpg.mvYAxis, tag="db_y", no_gridlines=True, invert=True):
                    dpg.set_axis_ticks("db_y", tuple(zip(labels, self.layout["centres"])))
                    dpg.set_axis_limits("db_y", float(x[0]) - 1.0, float(x[-1]) + 1.0)
                    zeros = np.zeros_like(x)
                    dpg.add_bar_series(zeros, x - BAR_WIDTH / 2, weight=BAR_WIDTH, label="query", tag="db_query",
                                       horizontal=True)
                    dpg.add_bar_series(zeros, x + BAR_WIDTH / 2, weight=BAR_WIDTH, label="preview frame",
                                       tag="db_frame_bars", horizontal=True)
        theme = self.ctx.theme
        theme.series("db_query", QUERY_COLOR, bar=True)
        theme.series("db_frame_bars", PREVIEW_COLOR, bar=True)

    # -- what the user (or a script) does ------------------------------------------------------
    def _on_row(self, sender, value, i):
        self.select_range(i)

    def _on_selection_field(self, sender, value):
        self.selection = (int(self.dpg.get_value("db_from")), int(self.dpg.get_value("db_to")))

    def _error(self, message: str) -> None:
        self.ctx.actions.show_error("Database", message)

    def run_command(self, a: dict) -> None:
        """The ``database`` command: ``op`` ``select`` (range), ``frame`` (db_frame), ``play``, ``pause``,
        ``scrub`` (source_frame), ``selection`` (start, stop), ``mark`` (end: in/out), ``copy`` or ``why_not``."""
        op = a["op"]
        if op == "select":
            self.select_range(int(a["range"]))
        elif op == "frame":
            self.show_frame(int(a["db_frame"]), origin="range")
        elif op in ("play", "pause"):
            self.set_playing(op == "play")
        elif op == "scrub":
            self.scrub_to_source(int(a["source_frame"]))
        elif op == "selection":
            self.set_selection(int(a["start"]), int(a["stop"]))
        elif op == "mark":
            self.mark(a["end"])
        elif op == "copy":
            self.copy_range()
        elif op == "why_not":
            self.why_not()
        else:
            raise ValueError(f"unknown database op {op!r}")

    def why_not(self) -> None:
        """Ask why the shown tick's search did not choose the previewed frame (the Search Candidates panel
        answers: app.why_not_probe)."""
        if self.frame >= 0:
            self.ctx.actions.why_not(int(self.frame))

    def select_range(self, index: int) -> bool:
        """Preview database range ``index`` from its first frame; its whole span becomes the selection."""
        if not 0 <= int(index) < len(self.ranges):
            self._error(f"{self.ctx.engine.db.name}: no database range {index} (it has {len(self.ranges)})")
            return False
        r = self.ranges[int(index)]
        self.selected = r
        self.frame = r.db_start
        self.origin = "range"
        self.set_selection(r.source_start, r.source_stop, check=False)
        self._configure_range()
        return True

    def show_frame(self, frame: int, origin: str = "candidate") -> bool:
        """Preview database frame ``frame`` (a clicked search candidate): its range is selected, playing stops."""
        r = range_of_frame(self.ranges, int(frame))
        if r is None:
            self._error(f"{self.ctx.engine.db.name}: no database frame {frame} (it has "
                        f"{self.ctx.engine.db.n_frames})")
            return False
        if self.selected is None or self.selected.index != r.index:
            self.selected = r
            self.set_selection(r.source_start, r.source_stop, check=False)
            self._configure_range()
        self.frame = int(frame)
        self.origin = origin
        self.set_playing(False)
        return True

    def scrub_to_source(self, source_frame: int) -> None:
        if self.selected is not None:
            self.frame = self.selected.db_frame(source_frame)
            self.origin = "range"

    def set_playing(self, playing: bool) -> None:
        self.playing = bool(playing) and self.selected is not None
        self._last_frame_counter = None
        if self.dpg.does_item_exist("db_play"):
            self.dpg.configure_item("db_play", label="Pause" if self.playing else "Play")

    def set_selection(self, start: int, stop: int, check: bool = True) -> bool:
        """The selection in the file's frames ``[start, stop)``; with ``check`` a bad one is reported."""
        if check and self.selected is not None:
            try:
                manifest_range(self.selected, start, stop)
            except RangeSelectionError as e:
                self._error(str(e))
                return False
        self.selection = (int(start), int(stop))
        if self.dpg.does_item_exist("db_from"):
            self.dpg.set_value("db_from", self.selection[0])
            self.dpg.set_value("db_to", self.selection[1])
        return True

    def mark(self, end: str) -> None:
        """Set the selection's start (``in``) or end (``out``, exclusive: after the previewed frame)."""
        if self.selected is None or self.frame < 0:
            self._error(f"{self.ctx.engine.db.name}: select a range first")
            return
        f = self.selected.source_frame(self.frame)
        a, b = self.selection
        self.set_selection(f, b, check=False) if end == "in" else self.set_selection(a, f + 1, check=False)

    def copy_range(self) -> str:
        """Put the selection on the clipboard as a manifest range (and show it); "" and an error when the
        selection is empty or outside the range."""
        if self.selected is None:
            self._error(f"{self.ctx.engine.db.name}: select a range first (nothing to copy)")
            return ""
        try:
            entry = manifest_range(self.selected, *self.selection)
        except InputError as e:
            self._error(str(e))
            return ""
        self.copied = json.dumps(entry)
        try:
            self.dpg.set_clipboard_text(self.copied)
        except Exception:      # no clipboard (a bare X server): the text field still shows it
            pass
        self.dpg.set_value("db_copied", f"copied ({self.selected.file}): {self.copied}")
        return self.copied

    def _configure_range(self) -> None:
        dpg = self.dpg
        r = self.selected
        for i in range(len(self.rows)):
            dpg.set_value(f"db_row_{i}", i == r.index)
        dpg.configure_item("db_scrub", min_value=r.source_start, max_value=r.source_stop - 1)
        self._scroll_to = r.index      # scrolled into view once the table has been drawn (see update)

    # -- per frame ----------------------------------------------------------------------------
    def _advance(self, view: View) -> None:
        """While playing, one database frame per studio frame, looping over the selection."""
        if not self.playing or self.selected is None:
            return
        if self._last_frame_counter is None:
            self._last_frame_counter = view.frame
            return
        n = view.frame - self._last_frame_counter
        self._last_frame_counter = view.frame
        r = self.selected
        lo = r.db_frame(max(self.selection[0], r.source_start))
        hi = r.db_frame(min(self.selection[1], r.source_stop) - 1)
        if hi < lo:
            lo, hi = r.db_start, r.db_stop - 1
        f = self.frame + n
        if f > hi:
            if self.loop:
                f = lo + (f - lo) % (hi - lo + 1)
            else:
                f = hi
                self.set_playing(False)
        self.frame = int(max(f, lo))

    def _scroll_table(self) -> None:
        """Bring the selected row into the table's view (rows are of equal height)."""
        dpg = self.dpg
        most = float(dpg.get_y_scroll_max("db_table"))
        shown = float(TABLE_HEIGHT_PX)
        if most <= 0.0 or shown <= 0.0:
            return
        row = (most + shown) / (len(self.rows) + 1)          # the header row is one more
        dpg.set_y_scroll("db_table", float(np.clip((self._scroll_to + 1) * row - shown / 2, 0.0, most)))
        self._scroll_to = None

    def update(self, view: View) -> None:
        if self._scroll_to is not None:
            self._scroll_table()
        self._advance(view)
        db, features = self.ctx.engine.db, self.ctx.engine.features
        r = self.selected
        if r is None or self.frame < 0:
            if self._shown is not None:
                self.ctx.actions.set_preview(self.key, ())
                self._shown = None
            self.last = {"selected": None, "frame": -1, "preview": None}
            return
        source = r.source_frame(self.frame)
        what = "candidate" if self.origin == "candidate" else "preview"
        label = f"{what}: {PurePosixPath(r.file).name.split('.')[0]} {source}" + (" (mirror)" if r.mirrored else "")
        shown = (self.frame, label)
        if shown != self._shown:
            self.ctx.actions.set_preview(self.key, (database_preview(db, features, self.frame, label),))
            self._shown = shown
        self.text.set("db_status", f"{r.label()}  {', '.join(r.tags)}\n{what} file frame {source} "
                                   f"(database frame {self.frame}), {(self.frame - r.db_start) / r.fps:.2f} s "
                                   f"of {r.seconds:.2f} s")
        if self.dpg.get_value("db_scrub") != source:
            self.dpg.set_value("db_scrub", source)
        # the previewed frame's features beside the displayed query (the picked tick while scrubbing)
        x = self.layout["x"]
        frame_vec = np.asarray(features.normalized[self.frame], np.float64)
        snap = view.snap()
        query = None if snap is None else np.asarray(snap.query, np.float64)
        self.dpg.set_value("db_frame_bars", [frame_vec, x + BAR_WIDTH / 2])
        self.dpg.set_value("db_query", [query if query is not None else np.zeros_like(x), x - BAR_WIDTH / 2])
        cost = float(np.sum((query - frame_vec) ** 2)) if query is not None else float("nan")
        inspected = SHORT.get(view.inspected, view.inspected)
        self.dpg.configure_item("db_query", label=f"query ({inspected}, tick {view.tick_number})")
        self.text.set("db_cost", f"|query - preview|^2 = {fmt_num(cost)} (search cost, no bias)")
        self.last = {"selected": r.index, "file": r.file, "frame": self.frame, "source_frame": int(source),
                     "origin": self.origin, "playing": self.playing, "selection": list(self.selection),
                     "preview": label, "cost": cost, "tick": view.tick_number, "copied": self.copied}

    def state(self) -> dict:
        out = {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in self.last.items()}
        out["rows"] = len(self.rows)
        out["copied"] = self.copied
        return out
