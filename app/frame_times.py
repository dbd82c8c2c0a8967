"""Rolling frame times: how long each part of a studio frame took, in milliseconds (no GUI)."""
from __future__ import annotations

from collections import deque

import numpy as np


class FrameTimes:
    """Rolling per-part frame times in milliseconds (pure, for tests and the benchmark).

    A part is only added in the frames it happened in (e.g. a controller's step only in frames that
    finished a tick), so a frame without one does not pull its median towards zero.
    """

    def __init__(self, n: int = 240):
        self.n = n
        self.parts: dict[str, deque] = {}
        self.frames: deque = deque(maxlen=n)
        self._medians: dict = {}     # part -> median, until the next add (the menu asks every frame)

    def add(self, frame_ms: float, parts: dict) -> None:
        self._medians.clear()
        self.frames.append(float(frame_ms))
        for k, v in parts.items():
            self.parts.setdefault(k, deque(maxlen=self.n)).append(float(v))

    def median(self, part: str | None = None) -> float:
        m = self._medians.get(part)
        if m is None:
            d = self.frames if part is None else self.parts.get(part)
            m = self._medians[part] = float(np.median(d)) if d else float("nan")
        return m

    def fps(self) -> float:
        m = self.median()
        return 1000.0 / m if m and np.isfinite(m) and m > 0 else float("nan")

    def series(self, part: str | None = None) -> np.ndarray:
        d = self.frames if part is None else self.parts.get(part, ())
        return np.asarray(d, np.float64)


def per_tick_ms(finished, names) -> dict[str, float]:
    """Mean milliseconds per tick of each controller over the ticks finished in one frame, from the
    worker's ``[(tick, {name: ms}), ...]``; empty when no tick finished (paused, or a frame faster
    than the tick rate), so those frames add no controller time instead of a zero."""
    out = {}
    for name in names:
        ms = [m[name] for _, m in finished if name in m]
        if ms:
            out[name] = float(np.mean(ms))
    return out
