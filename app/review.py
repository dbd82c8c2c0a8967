"""Reopening a session in the studio (``lmm-studio --open SESSION``, File > Open session...).

The session's controllers are rebuilt and stepped by a :class:`lmm.session.seek.SessionSeeker`; the
studio shows them instead of its live ones, paused, with the timeline covering the whole session.
:class:`SessionHistory` stands in for the rewind history the panels read: asking for any tick
re-simulates it from the nearest controller-state checkpoint (one a second, kept as the seeker passes),
and the ticks stepped on the way fill the history's plots, so every panel shows the picked tick. Going
live again (Home, Play) leaves the session and resets the live characters. The whole session's
per-channel cost timeline (:mod:`lmm.session.cost_timeline`) is worked out once, by a background job
started when the session opens (in a child process: :mod:`app.cost_timeline_job`): reopening and seeking
wait for none of it.
"""
from __future__ import annotations

from .history import History, Tick


class SessionHistory:
    """Every tick of a session as the panels read a history (numbers ``1 .. ticks``, the live history's
    numbering: tick ``n`` is the pose after ``n`` steps). Plots read the ring of the ``capacity`` ticks
    stepped up to the last one shown (NaN elsewhere); everything else is asked of that ring too."""

    is_session = True                        # what the status line says (SESSION, not PAUSED)

    def __init__(self, seeker, capacity: int):
        self.seeker = seeker
        self.last = seeker.ticks
        self.ring = History(capacity)
        self._tuning: dict | None = None
        self._cost_job = None

    def start_cost_timeline(self, jobs, manifest_path=None) -> None:
        """Work out the session's channel cost timeline as a job of ``jobs`` (an :class:`app.jobs.Jobs`),
        in a child process (:mod:`app.cost_timeline_job`) on the database of ``manifest_path`` (default:
        the recorded one)."""
        from .cost_timeline_job import compute_in_child

        path = self.seeker.session.path
        self._cost_job = jobs.submit("cost-timeline", lambda job: compute_in_child(job, path, manifest_path))

    @property
    def cost_timeline(self):
        """``(timeline, status)``: the :class:`lmm.session.cost_timeline.CostTimeline` once worked out (else
        None) and one line while it is not ("" once it is)."""
        job = self._cost_job
        if job is None or job.cancelled:
            return None, "no channel cost timeline"
        if not job.finished:
            return None, f"working out the whole session's channel costs: {100 * (job.progress or 0.0):.0f} %"
        if job.error:
            return None, f"channel costs unavailable: {job.error}"
        return job.result, ""

    def close(self) -> None:
        """The session is left: stop the background work."""
        if self._cost_job is not None:
            self._cost_job.cancel()

    def __getattr__(self, name):             # window, times, has_series, capacity, count ...
        return getattr(self.ring, name)

    @property
    def newest_tick(self) -> int:
        return self.last if self.last > 0 else -1

    @property
    def oldest_tick(self) -> int:
        return 1 if self.last > 0 else -1

    def __len__(self) -> int:
        return self.last

    def contains(self, tick: int) -> bool:
        return 1 <= tick <= self.last

    def clamp(self, tick: int) -> int:
        return int(min(max(tick, 1), self.last)) if self.last > 0 else -1

    def latest(self) -> Tick | None:
        return self.get(self.last)

    def get(self, tick: int) -> Tick | None:
        """Tick ``tick``, re-simulated from the nearest checkpoint unless the ring holds it."""
        if not self.contains(tick):
            return None
        if not self.ring.contains(tick):
            self._simulate_to(tick)
        return self.ring.get(tick)

    def ticks_between(self, first: int, last: int) -> list[Tick]:
        return self.ring.ticks_between(first, last)

    def _simulate_to(self, tick: int) -> None:
        sk = self.seeker
        target = tick - 1                              # the step that makes tick ``tick``
        sk.go_before(target)
        if sk.tick < self.ring.newest_tick:            # going back: the ring starts again
            self.ring.clear()
        while sk.tick <= target:
            i = sk.tick
            _, snaps = sk.step()
            tuning = sk.tuning.to_dict()                 # the tick's tuning (the Tuning panel shows it) ...
            if tuning == self._tuning:                   # ... one dict while it does not change
                tuning = self._tuning
            self._tuning = tuning
            self.ring.append(Tick(i + 1, (i + 1) * sk.dt, snaps, {"input": sk.input_at(i), "tuning": tuning}))


def open_recorded_session(studio, path) -> bool:
    """Show the session at ``path`` in ``studio`` (see the module doc). A file that cannot be read, from
    another database or networks, or with other controllers than a running studio draws is refused in one
    line in the error dialog."""
    from lmm.errors import InputError
    from lmm.session.reader import check_identity, open_session
    from lmm.session.seek import SessionSeeker

    s = studio.session
    try:
        f = open_session(path)
        warnings = check_identity(f, s.db)
        seeker = SessionSeeker(f, s.db, s.features)
    except (InputError, OSError, ValueError) as e:
        studio.errors.show("Session", str(e) if str(path) in str(e) else f"{path}: {e}")
        return False
    if getattr(studio, "panels", None) and set(seeker.controllers) != set(s.controllers):
        f.close()
        studio.errors.show("Session", f"{path}: its controllers ({', '.join(seeker.controllers)}) are not the "
                                      f"studio's ({', '.join(s.controllers)}): open it with lmm-studio --open {path}")
        return False
    for line in warnings:
        studio.errors.inform("Session", line)
    live_controllers, live_history = dict(s.controllers), s.history
    if studio.reviewed is not None:                  # another session was open: the live parts are its
        studio.playback.on_leave()
        live_controllers, live_history = dict(s.controllers), s.history
    studio.reviewed = f
    s.controllers.clear()
    s.controllers.update(seeker.controllers)         # what the panels ask the controllers is the session's
    s.history = session_history = SessionHistory(seeker, live_history.capacity)
    session_history.start_cost_timeline(s.jobs, getattr(s.manifest, "path", None))
    studio.playback.review(s.history)

    def leave() -> None:
        """Back to the live characters (reset: the live history was left behind)."""
        shown = set(s.controllers)
        session_history.close()
        s.controllers.clear()
        s.controllers.update(live_controllers)
        s.history = studio.playback.history = live_history
        studio.reviewed = None
        studio.playback.on_leave = None
        f.close()
        s.reset()
        viewport = getattr(studio, "viewport", None)
        for name in live_controllers:
            if name not in shown and viewport is not None:
                viewport.add_controller(name)

    studio.playback.on_leave = leave
    return True
