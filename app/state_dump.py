"""The frame loop's observer: what the studio did, frame by frame, for the GUI tests and benchmarks
(``--dump-state``, a JSON file written at exit), kept out of the frame loop.

The studio calls one :class:`FrameObserver` at fixed points of each frame; without ``--dump-state``
it is the do-nothing base class. :class:`StateDump` records the ticks (with the frame and tuning they
were stepped with), each frame's timings, recordings and labelled captures of every panel, and
measures its own work so the studio's frame times leave it out.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import numpy as np

from lmm.data.jsonio import write_json

from . import layout_files


def _roots(tick) -> dict:
    return {} if tick is None else {n: [float(x) for x in s.pose.global_positions[0]]
                                    for n, s in tick.snapshots.items()}


class FrameObserver:
    """The hooks of the frame loop; each does nothing here."""

    def ticks_finished(self, finished) -> None:
        """The ticks the worker finished (``[(tick, extra)]``)."""

    def ticks_due(self, session, n: int) -> None:
        """``n`` ticks are about to be handed to the worker with the tuning as it is now."""

    def frame_shown(self, frame: int, view, session, n: int, viewport_roots: dict) -> None:
        """The panels and the 3D view show ``view``; ``n`` ticks are being submitted."""

    def frame_timed(self, frame_ms: float, parts: dict) -> None:
        """The frame's duration and its parts (ms); the observer may add its own part."""

    def spent_s(self) -> float:
        """Seconds of the current frame spent in the observer so far (not the studio's time)."""
        return 0.0

    def recording_started(self, frame: int, paths: dict) -> None:
        pass

    def recording_stopped(self, frame: int, result) -> None:
        pass

    def capture(self, label: str, frame: int, tick, panels: Callable[[], dict]) -> None:
        """A test script asks to keep what every panel shows now (``panels()``) under ``label``."""

    def finish(self, final: Callable[[], dict]) -> None:
        """The studio shuts down; ``final()`` is its end state."""


class StateDump(FrameObserver):
    """What the studio did, frame by frame, for the tests: written as JSON at exit."""

    def __init__(self, path):
        self.path = Path(path)
        self.data = {"frames": [], "ticks": [], "labels": {}, "recordings": []}
        self._submitted: dict[int, int] = {}          # tick -> frame whose inputs it was stepped with
        self._tuning_at_submit: dict[int, dict] = {}
        self._tuning_seen = None
        self._spent = 0.0
        self._record: dict | None = None

    def ticks_finished(self, finished) -> None:
        t0 = time.perf_counter()
        self._spent = 0.0
        for tick, _ in finished:
            self.data["ticks"].append({
                "tick": tick.tick, "frame_submitted": self._submitted.get(tick.tick),
                "tuning_seen": self._tuning_at_submit.get(tick.tick), "roots": _roots(tick),
                "desired_speed": {n: float(np.linalg.norm(s.desired_velocity)) for n, s in tick.snapshots.items()},
                "input": dict(vars(tick.extra["input"]))})
        self._spent += time.perf_counter() - t0

    def ticks_due(self, session, n: int) -> None:
        t0 = time.perf_counter()
        self._tuning_seen = session.tuning.to_dict() if n else None
        self._spent += time.perf_counter() - t0

    def spent_s(self) -> float:
        return self._spent

    def frame_shown(self, frame: int, view, session, n: int, viewport_roots: dict) -> None:
        first = session.tick + 1            # the ticks submitted this frame (still to be stepped)
        for k in range(n):
            self._submitted[first + k] = frame
            self._tuning_at_submit[first + k] = self._tuning_seen
        self._record = {"frame": frame, "ticks": n, "displayed_tick": view.tick_number,
                        "newest_tick": session.history.newest_tick, "live": view.live, "paused": view.paused,
                        "roots": _roots(session.history.latest()), "viewport_roots": viewport_roots}
        self.data["frames"].append(self._record)

    def frame_timed(self, frame_ms: float, parts: dict) -> None:
        parts["dump"] = self._spent * 1e3
        if self._record is not None:
            self._record.update({"ms": {k: round(float(v), 4) for k, v in parts.items()},
                                 "frame_ms": round(frame_ms, 4), "t": round(time.perf_counter(), 6),
                                 "cpu": round(time.process_time(), 6)})
            self._record = None

    def recording_started(self, frame: int, paths: dict) -> None:
        self.data["recordings"].append({"started": frame, "paths": {k: str(v) for k, v in paths.items()}})

    def recording_stopped(self, frame: int, result) -> None:
        if self.data["recordings"]:
            self.data["recordings"][-1].update(
                written={k: str(v) for k, v in result.paths.items()}, stopped=frame,
                frames=result.frames, message=result.message,
                exists={k: Path(v).exists() for k, v in result.paths.items()})

    def capture(self, label: str, frame: int, tick, panels: Callable[[], dict]) -> None:
        self.data["labels"][label] = {
            "frame": frame, "displayed_tick": -1 if tick is None else tick.tick, "snapshot_roots": _roots(tick),
            "snapshot_query": {} if tick is None else {n: np.asarray(s.query).tolist()
                                                       for n, s in tick.snapshots.items()},
            "panels": panels()}

    def finish(self, final: Callable[[], dict]) -> None:
        self.data.update(final())
        write_json(self.path, self.data, indent=None)


def panel_state(studio) -> dict:
    """What every panel, the windows, the menu and the message dialog of ``studio`` show now."""
    out = {key: panel.state() for key, panel in studio.panels.items()}
    out["windows"] = studio.layouts.window_state()
    out["menu"] = studio.menu.state()
    out["dialog"] = {"title": studio.errors.title, "shown": studio.errors.visible}
    return out


def final_state(studio) -> dict:
    """The end state of ``studio`` the dump closes with."""
    s, ft = studio.session, studio.frame_times
    return dict(
        frames_run=studio.frame_index, tick_count=s.tick, controllers=s.names,
        shared_tuning=all(getattr(c, "tuning", None) is s.tuning for c in s.controllers.values()),
        lmm_problem=studio.lmm_problem, errors=list(studio.errors.shown), layout=studio.layouts.name,
        layout_switches=studio.layouts.switches, final=panel_state(studio),
        frame_times={"median_ms": ft.median(), "parts_ms": {k: ft.median(k) for k in ft.parts}},
        prepared=studio.preparer.state(),
        ui_antialiasing={k: v for k, v in studio.dpg.get_app_configuration().items() if k.startswith("anti_")},
        user_layout=str(layout_files.user_layout_path()))
