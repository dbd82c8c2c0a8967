"""How fast the simulation runs against the wall clock: the studio steps the controllers by the wall
time a frame took, but at most a few ticks a frame (app.playback), so a slow machine or a loaded one
simulates less than the time that passed. The menu bar says so with the ratio, simulated over wall time
of the last few seconds; in fixed-step runs (scripts, --frames) one tick a frame is the rule and the
note says that too."""
from __future__ import annotations

from collections import deque

WINDOW_S = 3.0          # the ratio is over the last seconds of playing frames
BEHIND_BELOW = 0.95     # a ratio under this is shown (a frame's jitter stays quiet)
MIN_WALL_S = 1.0        # and only once this much playing time has been seen


class RealTimeRatio:
    def __init__(self, window_s: float = WINDOW_S):
        self.window_s = float(window_s)
        self._frames: deque = deque()        # (wall seconds, simulated seconds) of playing frames
        self._wall = 0.0
        self._sim = 0.0

    def add(self, wall_s: float, simulated_s: float, playing: bool) -> None:
        """One frame: ``wall_s`` it took, ``simulated_s`` of ticks it asked for; a paused, scrubbed or
        reviewing frame (``playing`` False) starts the measure again."""
        if not playing:
            self._frames.clear()
            self._wall = self._sim = 0.0
            return
        self._frames.append((float(wall_s), float(simulated_s)))
        self._wall += wall_s
        self._sim += simulated_s
        while self._frames and self._wall - self._frames[0][0] > self.window_s:
            w, s = self._frames.popleft()
            self._wall -= w
            self._sim -= s

    def ratio(self) -> float | None:
        """Simulated over wall time of the window (None until :data:`MIN_WALL_S` of playing time)."""
        return self._sim / self._wall if self._wall >= MIN_WALL_S else None

    def note(self, fixed_step: bool = False) -> str:
        """The menu bar's words ("" when in real time or not known yet)."""
        r = self.ratio()
        if r is None or r >= BEHIND_BELOW:
            return ""
        return f"behind real time: {r:.2f}x" + (" (fixed step: one tick a frame)" if fixed_step else "")
