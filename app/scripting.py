"""Test hooks: a script of timed actions the studio runs (``--script``), and the JSON state dump it
writes at exit (``--dump-state``). The GUI tests drive the real studio with these."""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from lmm.data.jsonio import write_json

if TYPE_CHECKING:
    from .studio import Studio


def _roots(tick) -> dict:
    return {} if tick is None else {n: [float(x) for x in s.pose.global_positions[0]]
                                    for n, s in tick.snapshots.items()}


class Script:
    """Timed actions: ``[{"frame": 30, "do": "set_tuning", "field": ..., "value": ...}, ...]``.

    Actions: ``set_tuning`` (field, value[, channel]) sets the slider and fires its callback;
    ``key_down`` / ``key_up`` (key); ``record_start`` (path[, which]) / ``record_stop``; ``layout``
    (name or path); ``follow`` (on[, overlay]: follow the loaded reference BVH); ``pause`` / ``resume`` / ``live`` / ``scrub`` (tick, or back: n ticks) / ``step`` (n);
    ``open`` (kind: a file dialog kind, path); ``inspect`` (controller); ``capture`` (label);
    ``screenshot`` (path); ``sort`` (key[, descending]); ``coverage`` (mode: tag or speed, channel: a
    feature channel's name); ``help`` (Help > Keys and mouse); ``dismiss`` (OK on the message shown); ``quit``;
    ``quit_when_exists`` (path: quit on the first frame that file exists); ``write_rects`` (path, items:
    write the screen rectangles of those items as JSON, for tests that click them with xdotool);
    ``show`` (window[, show]); ``window_size`` (window, width, height: resize a window); ``click_candidate`` (row: preview a Search Candidates row); ``database`` (op: ``select`` (range),
    ``frame`` (db_frame), ``play``, ``pause``, ``scrub`` (source_frame), ``selection`` (start, stop),
    ``mark`` (end: in/out), ``copy``) drives the Database panel;
    ``motion_search`` (source: timeline or file, seconds, file, frames, in, top: runs that search);
    ``ragdoll`` (key: enabled, residual or drawn, value; or reset: true) sets the simulated ragdolls.
    """

    def __init__(self, actions: list[dict]):
        self.actions = sorted(actions, key=lambda a: int(a.get("frame", 0)))
        self.i = 0
        self.quit_files: list[Path] = []
        self.keys: set[str] = set()           # keys the script holds down
        self.captures: list[str] = []         # labels to capture after this frame's panels updated

    @classmethod
    def load(cls, path) -> "Script":
        data = json.loads(Path(path).read_text())
        return cls(data["actions"] if isinstance(data, dict) else data)

    def run(self, studio: "Studio", frame: int) -> None:
        if any(p.exists() for p in self.quit_files):
            studio.quit()
        while self.i < len(self.actions) and int(self.actions[self.i].get("frame", 0)) <= frame:
            a = self.actions[self.i]
            self.i += 1
            self._do(studio, a)

    def _do(self, s: "Studio", a: dict) -> None:
        do = a["do"]
        p = s.playback
        simple = {"record_stop": s.stop_recording, "pause": p.pause, "resume": p.resume, "live": p.go_live,
                  "quit": s.quit, "help": s.menu.show_keys_help, "dismiss": s.errors.dismiss}
        if do in simple:
            simple[do]()
        elif do == "set_tuning":
            s.panels["tuning"].set_field(a["field"], a["value"], a.get("channel"))
        elif do == "key_down":
            self.keys.add(a["key"])
        elif do == "key_up":
            self.keys.discard(a["key"])
        elif do == "record_start":
            s.start_recording(a["path"], tuple(a.get("which", ("mm", "lmm"))))
        elif do == "layout":
            s.switch_layout(a["name"])
        elif do == "scrub":
            p.scrub_to(a["tick"] if "tick" in a else s.session.history.newest_tick - int(a["back"]))
        elif do == "step":
            p.step(int(a.get("n", 1)))
        elif do == "open":
            s.dialogs.handle(a["kind"], a["path"])
        elif do == "follow":
            s.follow_reference(bool(a.get("on", True)))
            if "overlay" in a:
                s.panels["recording"].set_overlay(bool(a["overlay"]))
        elif do == "inspect":
            s.set_inspected(a["controller"])
        elif do == "capture":
            self.captures.append(a["label"])
        elif do == "screenshot":
            s.request_screenshot(a["path"])
        elif do == "motion_search":
            s.panels["motion_search"].run_script(a)
        elif do == "sort":
            s.panels["candidates"].set_sort(a["key"], bool(a.get("descending", False)))
        elif do == "show":
            s.layouts.show_window(a["window"], bool(a.get("show", True)))
        elif do == "click_candidate":
            s.panels["candidates"].click_row(int(a["row"]))
        elif do == "database":
            self._database(s.panels["database"], a)
        elif do == "coverage":
            if "mode" in a:
                s.panels["coverage"].set_mode(a["mode"])
            if "channel" in a:
                s.panels["coverage"].set_channel(a["channel"])
        elif do == "ragdoll":          # key (enabled, residual, drawn), value; or reset: true
            if a.get("reset"):
                s.reset_ragdolls()
            else:
                s.set_ragdoll(a["key"], a["value"])
        elif do == "quit_when_exists":  # external tests (real key presses) end the run by creating a file
            self.quit_files.append(Path(a["path"]))
        elif do == "window_size":       # as a user dragging the window's edge would
            from .panels.common import window_tag

            s.dpg.configure_item(window_tag(a["window"]), width=int(a["width"]), height=int(a["height"]))
        elif do == "write_rects":
            dpg = s.dpg
            rects = {item: list(dpg.get_item_rect_min(item)) + list(dpg.get_item_rect_max(item))
                     for item in a["items"]}
            write_json(a["path"], rects)
        else:
            raise ValueError(f"unknown script action {do!r}")


    @staticmethod
    def _database(panel, a: dict) -> None:
        op = a["op"]
        if op == "select":
            panel.select_range(int(a["range"]))
        elif op == "frame":
            panel.show_frame(int(a["db_frame"]), origin="range")
        elif op in ("play", "pause"):
            panel.set_playing(op == "play")
        elif op == "scrub":
            panel.scrub_to_source(int(a["source_frame"]))
        elif op == "selection":
            panel.set_selection(int(a["start"]), int(a["stop"]))
        elif op == "mark":
            panel.mark(a["end"])
        elif op == "copy":
            panel.copy_range()
        else:
            raise ValueError(f"unknown database op {op!r}")


class Screenshots:
    """PNG files of the whole window (``--screenshot``, the ``screenshot`` script action)."""

    def __init__(self, dpg):
        self.dpg = dpg
        self.requested: list[Path] = []
        self._temporary: dict[Path, Path] = {}     # target -> the file dearpygui writes first
        self._failed: list[str] = []               # one line per target that cannot be written

    def request(self, path) -> Path:
        """Ask dearpygui to save the whole window during the next frame it renders. dearpygui writes
        a hidden temporary file beside the target, renamed over it once complete (:meth:`finish`),
        so a full disk or a crash never leaves half a PNG under the target's name; a target that
        cannot be written is reported by :meth:`finish`."""
        from viewer.png import check_writable

        out = Path(path)
        try:
            check_writable(out)
        except OSError as e:
            self._failed.append(f"{e.filename}: {e.strerror}")
            return out
        tmp = out.with_name(f".{out.name}.{os.getpid()}.partial.png")
        tmp.unlink(missing_ok=True)
        self.dpg.output_frame_buffer(file=str(tmp))
        self.requested.append(out)
        self._temporary[out] = tmp
        return out

    def finish(self, report_error) -> int:
        """Render (without simulating) until every requested file is on disk; 1 when one never came."""
        def done(p):
            return self._temporary[p].exists() or (p.exists() and not self._temporary[p].exists())

        pending = [p for p in self.requested if not done(p)]
        tries = 0
        while pending and tries < 5:
            self.dpg.render_dearpygui_frame()
            tries += 1
            pending = [p for p in pending if not done(p)]
        for out, tmp in list(self._temporary.items()):
            if tmp.exists():
                try:
                    os.replace(tmp, out)
                except OSError as e:
                    tmp.unlink(missing_ok=True)
                    self._failed.append(f"{out}: cannot write ({e.strerror})")
        for p in pending:
            report_error("Screenshot", f"{p}: dearpygui did not write the screenshot")
        for line in self._failed:
            report_error("Screenshot", line)
        failed = bool(pending or self._failed)
        self._temporary.clear()
        self._failed = []
        return 1 if failed else 0


class StateDump:
    """What the studio did, frame by frame, for the tests: written as JSON at exit."""

    def __init__(self, path):
        self.path = Path(path)
        self.data = {"frames": [], "ticks": [], "labels": {}, "recordings": []}
        self._submitted: dict[int, int] = {}          # tick -> frame whose inputs it was stepped with
        self._tuning_at_submit: dict[int, dict] = {}

    def ticks(self, finished) -> None:
        """The ticks the worker finished (with the frame and tuning they were submitted with)."""
        for tick, _ in finished:
            self.data["ticks"].append({
                "tick": tick.tick, "frame_submitted": self._submitted.get(tick.tick),
                "tuning_seen": self._tuning_at_submit.get(tick.tick), "roots": _roots(tick),
                "desired_speed": {n: float(np.linalg.norm(s.desired_velocity)) for n, s in tick.snapshots.items()},
                "input": dict(vars(tick.extra["input"]))})

    def frame(self, frame: int, view, session, submitted: int, tuning_seen, viewport_roots) -> dict:
        first = session.tick + 1            # the ticks submitted this frame (still to be stepped)
        for k in range(submitted):
            self._submitted[first + k] = frame
            self._tuning_at_submit[first + k] = tuning_seen
        rec = {"frame": frame, "ticks": submitted, "displayed_tick": view.tick_number,
               "newest_tick": session.history.newest_tick, "live": view.live, "paused": view.paused,
               "roots": _roots(session.history.latest()), "viewport_roots": viewport_roots}
        self.data["frames"].append(rec)
        return rec

    def capture(self, label: str, frame: int, tick, panels: dict) -> None:
        """What every panel shows now, under ``label``."""
        self.data["labels"][label] = {
            "frame": frame, "displayed_tick": -1 if tick is None else tick.tick, "snapshot_roots": _roots(tick),
            "snapshot_query": {} if tick is None else {n: np.asarray(s.query).tolist()
                                                       for n, s in tick.snapshots.items()},
            "panels": panels}

    def write(self, **final) -> None:
        self.data.update(final)
        write_json(self.path, self.data, indent=None)
