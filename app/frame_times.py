"""Rolling frame times: how long each part of a studio frame took, in milliseconds (no GUI)."""
from __future__ import annotations

import numpy as np


class _Ring:
    """The last ``n`` floats in a preallocated array: appending writes one slot, and reading them oldest
    first is one copy (not a conversion of a deque's Python floats, which the Stats panel asked for
    three times a frame)."""

    __slots__ = ("_buf", "_head", "_count")

    def __init__(self, n: int):
        self._buf = np.empty(n)
        self._head = self._count = 0

    def append(self, value: float) -> None:
        n = len(self._buf)
        self._buf[self._head] = value
        self._head = (self._head + 1) % n
        if self._count < n:
            self._count += 1

    def __len__(self) -> int:
        return self._count

    def array(self) -> np.ndarray:
        """A new array of the values, oldest first."""
        if self._count < len(self._buf):
            return self._buf[:self._count].copy()
        return np.concatenate((self._buf[self._head:], self._buf[:self._head]))


class FrameTimes:
    """Rolling per-part frame times in milliseconds (pure, for tests and the benchmark).

    A part is only added in the frames it happened in (e.g. a controller's step only in frames that
    finished a tick), so a frame without one does not pull its median towards zero.
    """

    def __init__(self, n: int = 240):
        self.n = n
        self.parts: dict[str, _Ring] = {}
        self.frames = _Ring(n)
        self._medians: dict = {}     # part -> median, until the next add (the menu asks every frame)
        self._arrays: dict = {}      # part -> its times as an array, until the next add

    def add(self, frame_ms: float, parts: dict) -> None:
        self._medians.clear()
        self._arrays.clear()
        self.frames.append(float(frame_ms))
        for k, v in parts.items():
            ring = self.parts.get(k)
            if ring is None:
                ring = self.parts[k] = _Ring(self.n)
            ring.append(float(v))

    def median(self, part: str | None = None) -> float:
        m = self._medians.get(part)
        if m is None:
            d = self.frames if part is None else self.parts.get(part)
            m = self._medians[part] = median(self.series(part)) if d else float("nan")
        return m

    def percentile(self, q: float, part: str | None = None) -> float:
        """The ``q``-th percentile (``np.percentile``'s linear interpolation) of the frame times or a part."""
        d = self.frames if part is None else self.parts.get(part)
        return percentile(self.series(part), q) if d else float("nan")

    def fps(self) -> float:
        m = self.median()
        return 1000.0 / m if m and np.isfinite(m) and m > 0 else float("nan")

    def series(self, part: str | None = None) -> np.ndarray:
        """The frame times (or a part's), oldest first; one array per part until the next ``add``,
        shared by every caller (never write to it): the Stats panel and its percentile read the same
        series each frame."""
        a = self._arrays.get(part)
        if a is None:
            d = self.frames if part is None else self.parts.get(part)
            a = self._arrays[part] = d.array() if d is not None else np.zeros(0)
        return a


# np.median and np.percentile cost tens of microseconds a call in argument handling, many times the
# partial sort of a few hundred frame times they need; the studio asks for them every frame

def median(a: np.ndarray) -> float:
    """``np.median`` of a 1-D array (NaN when it holds one), from a partial sort."""
    n = len(a)
    if n == 0 or np.isnan(a).any():
        return float("nan")
    k = n // 2
    if n % 2:
        return float(np.partition(a, k)[k])
    part = np.partition(a, (k - 1, k))
    return float((part[k - 1] + part[k]) / 2.0)


def percentile(a: np.ndarray, q: float) -> float:
    """``np.percentile(a, q)`` (linear interpolation between the two nearest ranks) of a 1-D array
    (NaN when it holds one), from a partial sort."""
    n = len(a)
    if n == 0 or np.isnan(a).any():
        return float("nan")
    pos = q / 100.0 * (n - 1)
    lo = int(pos)
    hi = min(lo + 1, n - 1)
    part = np.partition(a, (lo, hi))
    below, above, t = part[lo], part[hi], pos - lo
    # numpy's interpolation: from the nearer of the two ends, so q=100 gives the maximum exactly
    return float(below + (above - below) * t if t < 0.5 else above - (above - below) * (1.0 - t))


def per_tick_ms(finished, names) -> dict[str, float]:
    """Mean milliseconds per tick of each controller over the ticks finished in one frame, from the
    worker's ``[(tick, {name: ms}), ...]``; empty when no tick finished (paused, or a frame faster
    than the tick rate), so those frames add no controller time instead of a zero."""
    out = {}
    for name in names:
        ms = [m[name] for _, m in finished if name in m]
        if ms:
            out[name] = sum(ms) / len(ms)     # np.mean of a short list costs more than the frame's step
    return out
