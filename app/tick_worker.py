"""The studio's per-frame pipelining: the next ticks are stepped on a worker thread while dearpygui
draws this frame. Not a background job (:mod:`app.jobs`): one long-lived thread, handed work before
every draw and collected at the start of the next frame."""
from __future__ import annotations

import queue
import threading

import numpy as np

from lmm.controller import InputState

from .history import Tick
from .session import Session

#: a snapshot's fields made on their first read that the default layout's panels read every frame
_DRAWN_LAZY_FIELDS = ("matched_pose_positions", "trajectory_positions", "trajectory_rotations", "query",
                      "simulation_position", "simulation_rotation")


class TickWorker:
    """Steps the session on a worker thread while the GUI draws.

    dearpygui releases the GIL while it renders a frame, so the controllers of the next tick run in
    parallel with the drawing of this one. The studio hands over a list of inputs (``submit``) just
    before it draws, and collects the finished ticks (``wait``) at the start of the next frame; in
    between it must not touch the session, and everything that changes the session (sliders,
    recording, replay, reset) runs after ``wait`` and before ``submit``.
    """

    def __init__(self, session: Session):
        self.session = session
        self._jobs: queue.Queue = queue.Queue()
        self._idle = threading.Event()
        self._idle.set()
        self._results: list = []
        self._error: BaseException | None = None
        self.prepared = None
        self._thread = threading.Thread(target=self._loop, name="studio-ticks", daemon=True)
        self._thread.start()

    def submit(self, inputs: list[InputState], prepare=None, release=None) -> None:
        """Step ``inputs``; then, when given, call ``prepare(newest tick)`` on the worker too (the panels'
        numeric work for the next frame, see ``Studio``): its result is ``prepared`` after ``wait``.
        ``release``: an object the GUI thread is done with, dropped on the worker (freeing a frame's
        prepared numbers, thousands of small objects, took 0.1 ms of the GUI thread's frame)."""
        if not inputs:
            return
        self._idle.clear()
        self._jobs.put((list(inputs), prepare, release))

    def wait(self) -> list[tuple[Tick, dict]]:
        """The ticks finished since the last call, with each one's per-controller milliseconds
        (``prepared`` then holds what the last job's ``prepare`` returned, or None)."""
        self._idle.wait()
        if self._error is not None:
            err, self._error = self._error, None
            raise err
        out, self._results = self._results, []
        self.session.deliver_reports()   # e.g. an unusable pose, reported once (app.session), on this thread
        return out

    def take_prepared(self):
        """What the last job's ``prepare`` returned (once; None when there was none or it failed)."""
        out, self.prepared = self.prepared, None
        return out

    def _loop(self) -> None:
        # numpy's error state is per thread: as on the GUI thread (app.commands.studio), a network given
        # absurd weights overflows without a warning line per tick; the pose guard says it once
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            self._jobs_until_closed()

    def _jobs_until_closed(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                return
            inputs, prepare, release = job
            job = release = None       # freed here, while the GUI thread draws
            self.prepared = None
            try:
                for inp in inputs:
                    tick = self.session.step(inp)
                    self._results.append((tick, dict(self.session.step_ms)))
                # the newest tick is the one a live studio draws next: what its panels read that is worked
                # out on the first read (the ghost poses' forward kinematics, the trajectory and query of a
                # tick that did not search) is worked out here, while the GUI thread draws, not on it
                for snap in tick.snapshots.values():
                    for name in _DRAWN_LAZY_FIELDS:
                        getattr(snap, name, None)
            except BaseException as e:  # handed to the GUI thread by wait()
                self._error = e
            else:
                if prepare is not None:
                    try:
                        self.prepared = prepare(tick)
                    except Exception:    # the GUI thread works it out itself, and reports what fails
                        self.prepared = None
            finally:
                self._idle.set()

    def close(self) -> None:
        self._idle.wait()
        self._jobs.put(None)
        self._thread.join(timeout=5.0)
