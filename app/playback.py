"""Playback: which tick the studio shows and how many ticks it simulates each frame (no GUI).

States: *live* (the newest tick is shown and the simulation runs), *paused* (nothing is simulated; the
shown tick may be any one the history holds: scrubbing and stepping move it). Stepping forward past the
newest tick while paused simulates that many new ticks. In live mode the simulation runs at the tick
rate off the frame clock (``fixed_step``: exactly one tick per frame, for reproducible runs). *Session*
(:mod:`app.review`): a reopened session is shown; nothing is simulated live, the shown tick is any of the
session's, playing moves it one tick a frame and going live leaves the session (``on_leave``).
"""
from __future__ import annotations

from app.history import History, Tick

MAX_TICKS_PER_FRAME = 4        # a slow frame catches up at most this many ticks ...
MAX_BACKLOG_S = 0.25           # ... and drops time beyond this backlog (no spiral of death)


class Playback:
    def __init__(self, history: History, dt: float, fixed_step: bool = False):
        self.history = history
        self.dt = float(dt)
        self.fixed_step = bool(fixed_step)
        self.paused = False
        self.scrub_tick: int | None = None       # None: the newest tick
        self.pending_steps = 0                   # ticks to simulate while paused (stepping forward)
        self._backlog_s = 0.0

    reviewing = False                            # a reopened session is shown (app.review)
    on_leave = None                              # called when going live leaves it

    @property
    def live(self) -> bool:
        return self.scrub_tick is None and not self.paused and not self.reviewing

    @property
    def mode(self) -> str:
        if self.reviewing:
            return "SESSION"
        return "LIVE" if self.live else ("PAUSED" if self.paused else "REWIND")

    def review(self, history) -> None:
        """Show a reopened session's history (:class:`app.review.SessionHistory`), paused on its first tick."""
        self.history, self.reviewing = history, True
        self.paused, self.pending_steps = True, 0
        self.scrub_tick = history.oldest_tick

    def toggle_pause(self) -> None:
        if self.paused:
            self.resume()
        else:
            self.pause()

    def pause(self) -> None:
        self.paused = True
        if self.scrub_tick is None and self.history.newest_tick >= 0:
            self.scrub_tick = self.history.newest_tick

    def resume(self) -> None:
        """Back to the live simulation from its newest tick (a scrubbed position is left); in a session, play
        it on from the shown tick."""
        self.paused = False
        if not self.reviewing:
            self.scrub_tick = None

    def go_live(self) -> None:
        if self.reviewing and self.on_leave is not None:
            self.on_leave()                      # gives the live history back (review off)
        self.reviewing = False
        self.paused = False
        self.scrub_tick = None

    def scrub_to(self, tick: int) -> None:
        """Pause and show ``tick`` (clamped to what the history holds)."""
        h = self.history
        if h.newest_tick < 0:
            return
        self.paused = True
        self.scrub_tick = h.clamp(int(tick))

    def step(self, n: int) -> None:
        """Move the shown tick by ``n`` (pausing first); forward past the newest tick simulates new ticks."""
        h = self.history
        if not self.paused:
            self.pause()
        current = self.scrub_tick if self.scrub_tick is not None else h.newest_tick
        target = current + int(n)
        if target > h.newest_tick and not self.reviewing:
            self.pending_steps += target - h.newest_tick
            self.scrub_tick = None
        else:
            self.scrub_tick = h.clamp(target)

    def displayed_tick(self) -> Tick | None:
        """The tick every panel shows: the newest when live, else the scrubbed one (None when empty)."""
        h = self.history
        if self.scrub_tick is None:
            return h.latest()
        t = h.get(self.scrub_tick)
        if t is None:  # fell out of the buffer
            self.scrub_tick = h.clamp(self.scrub_tick)
            t = h.get(self.scrub_tick)
        return t

    def ticks_due(self, frame_dt: float) -> int:
        """How many ticks to simulate for a frame that took ``frame_dt`` seconds."""
        if self.reviewing:                       # nothing live: playing shows the next tick
            if not self.paused:
                self.scrub_tick = self.history.clamp(self.scrub_tick + 1)
            return 0
        if self.paused:
            n, self.pending_steps = self.pending_steps, 0
            return n
        if self.fixed_step:
            return 1
        self._backlog_s = min(self._backlog_s + max(float(frame_dt), 0.0), MAX_BACKLOG_S)
        n = int(self._backlog_s / self.dt)
        self._backlog_s -= n * self.dt
        return min(n, MAX_TICKS_PER_FRAME)
