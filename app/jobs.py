"""Background work of the studio: one small service for everything that must not stall a frame.

A job is a named callable run on its own daemon thread. It is handed its :class:`Job`, through which it
reports progress (``job.report(fraction, message)``) and sees whether it was cancelled
(``job.cancelled``: a job checks it between steps; a cancelled job's result is dropped). Its result, or
one line saying why it failed, is delivered by :meth:`Jobs.poll` on the thread that polls (the GUI
thread, or the one that owns the session), never on the job's own thread: a job computes, its owner
applies.

The per-tick stepping (:class:`app.tick_worker.TickWorker`) is not a job: it is one long-lived thread
pipelined with the frame loop, handed work and collected every frame.
"""
from __future__ import annotations

import threading
from typing import Callable


def one_line(error: BaseException) -> str:
    """A failure as one line: its message's first line, or its type's name when it has no message."""
    text = str(error).strip().splitlines()
    return text[0] if text else type(error).__name__


class Job:
    """One piece of background work (made by :meth:`Jobs.submit`)."""

    def __init__(self, name: str, on_done, on_error, on_progress):
        self.name = name
        self._on_done, self._on_error, self._on_progress = on_done, on_error, on_progress
        self._finished = threading.Event()
        self._cancelled = False
        self.progress: float | None = None   # 0..1 as last reported (None: not said)
        self.message = ""                    # what it is doing, as last reported
        self._reported = False               # a report not yet delivered to on_progress
        self.result = None
        self.error = ""                      # one line when it failed ("" otherwise)

    # -- the job's side --------------------------------------------------------------------------
    @property
    def cancelled(self) -> bool:
        return self._cancelled

    def report(self, fraction: float | None = None, message: str = "") -> None:
        """Progress from the work (any thread); the owner sees it on its next poll."""
        self.progress, self.message, self._reported = fraction, message, True

    # -- the owner's side ------------------------------------------------------------------------
    def cancel(self) -> None:
        """Ask the work to stop; whatever it returns is dropped (no callback is called)."""
        self._cancelled = True

    @property
    def finished(self) -> bool:
        return self._finished.is_set()

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the work returned or failed (True), or ``timeout`` seconds passed (False)."""
        return self._finished.wait(timeout)

    def _run(self, work: Callable[["Job"], object]) -> None:
        try:
            self.result = work(self)
        except Exception as e:  # noqa: BLE001 - delivered to the owner as one line
            self.error = one_line(e)
        finally:
            self._finished.set()


class Jobs:
    """Runs jobs on threads and hands their outcomes to the owner when it polls."""

    def __init__(self):
        self._jobs: list[Job] = []
        self._lock = threading.Lock()

    def submit(self, name: str, work: Callable[[Job], object], on_done: Callable[[object], None] | None = None,
               on_error: Callable[[str], None] | None = None,
               on_progress: Callable[[float | None, str], None] | None = None) -> Job:
        """Start ``work(job)`` on a thread named ``name``. On a later :meth:`poll`: ``on_done(result)``,
        or ``on_error(one line)`` when it raised, or ``on_progress(fraction, message)`` while it runs and
        has reported since the last poll."""
        job = Job(name, on_done, on_error, on_progress)
        with self._lock:
            self._jobs.append(job)
        threading.Thread(target=job._run, args=(work,), name=name, daemon=True).start()
        return job

    def poll(self) -> list[Job]:
        """Deliver what the jobs did since the last poll, on the calling thread; returns the jobs that
        finished (cancelled ones included, whose outcome is dropped)."""
        with self._lock:
            done = [j for j in self._jobs if j.finished]
            running = [j for j in self._jobs if not j.finished]
            self._jobs = running
        for job in running:
            if job._reported and not job.cancelled and job._on_progress is not None:
                job._reported = False
                job._on_progress(job.progress, job.message)
        for job in done:
            if job.cancelled:
                continue
            if job.error:
                if job._on_error is not None:
                    job._on_error(job.error)
            elif job._on_done is not None:
                job._on_done(job.result)
        return done

    def running(self) -> list[Job]:
        """The jobs not yet delivered by :meth:`poll`."""
        with self._lock:
            return list(self._jobs)

    def wait(self, timeout: float | None = None) -> bool:
        """Block until every submitted job has finished (not delivered: :meth:`poll` does that); False
        when ``timeout`` seconds passed first."""
        import time

        deadline = None if timeout is None else time.monotonic() + timeout
        for job in self.running():
            left = None if deadline is None else max(deadline - time.monotonic(), 0.0)
            if not job.wait(left):
                return False
        return True
