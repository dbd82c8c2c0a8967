"""The studio's rewind buffer: the last N ticks of debug snapshots, plus numeric series for plots.

Pure Python and numpy (no GUI), so it is tested without a display.

Every tick the studio appends one :class:`Tick` (the snapshots of all controllers for that tick).
The buffer keeps the newest ``capacity`` ticks (20 s at 60 Hz by default) and addresses them by
their absolute tick number, so a scrub position stays on the same tick while new ticks arrive
(until that tick falls out of the buffer).

Plots read windows of numeric *series* (one value or vector per tick and controller, e.g. the best
cost or the 32 latent values) that are copied into preallocated ring arrays as ticks arrive, so a
plot never walks Python objects: ``history.window("lmm", "latent", end_tick, n)`` is one numpy gather.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

DEFAULT_SECONDS = 20.0
DEFAULT_RATE_HZ = 60.0


def _scalar(fn: Callable) -> Callable:
    def get(s):
        v = fn(s)
        return np.nan if v is None else float(v)
    return get


def _frame(fn: Callable) -> Callable:
    """A database frame number; -1 (none this tick) becomes NaN, so a plot shows a gap."""
    def get(s):
        v = fn(s)
        return np.nan if v is None or v < 0 else float(v)
    return get


def _vector(fn: Callable) -> Callable:
    return lambda s: fn(s)


def _timing(key: str) -> Callable:
    return lambda s: float(s.timings_us.get(key, np.nan)) if s.timings_us else np.nan


def _pose_root(s):
    return s.pose.global_positions[0]


# name -> (dims or None for "from the first value", extractor). Vectors that are None in a snapshot
# (e.g. MM has no latent) are stored as NaN.
SERIES: dict[str, Callable] = {
    "best_cost": _scalar(lambda s: s.best_cost),
    "nn_cost": _scalar(lambda s: s.nn_cost),
    "projected_cost": _scalar(lambda s: s.projected_cost),
    "matched_frame": _scalar(lambda s: s.matched_frame),
    "nn_frame": _scalar(lambda s: s.nn_frame),
    "projected_frame": _frame(lambda s: s.projected_frame),
    "searched": _scalar(lambda s: s.searched),
    "forced_search": _scalar(lambda s: s.forced_search),
    "transitioned": _scalar(lambda s: s.transitioned),
    "speed": _scalar(lambda s: float(np.linalg.norm(s.simulation_velocity))),
    "desired_speed": _scalar(lambda s: float(np.linalg.norm(s.desired_velocity))),
    "root_position": _vector(_pose_root),
    "query": _vector(lambda s: getattr(s, "query", None)),   # (D,) normalised query (the coverage trail)
    "latent": _vector(lambda s: s.latent),
    "matched_latent": _vector(lambda s: s.matched_latent),
    "search_us": _timing("search"),
    "step_us": _timing("total"),
}


@dataclass
class Tick:
    """One simulation tick: its number, simulation time and every controller's snapshot."""
    tick: int
    time_s: float
    snapshots: dict            # controller name -> DebugSnapshot
    extra: dict = field(default_factory=dict)  # studio-side per-tick data (e.g. the input); never plotted
    # studio-side numbers of this tick kept as series like the snapshots' (e.g. the pose error against a
    # followed reference): (controller, key) -> value; a series a tick does not give is NaN for it
    series: dict = field(default_factory=dict)


class History:
    """Ring buffer of the newest ``capacity`` ticks with per-controller numeric series."""

    def __init__(self, capacity: int = int(DEFAULT_SECONDS * DEFAULT_RATE_HZ)):
        if capacity < 1:
            raise ValueError(f"history capacity must be >= 1, got {capacity}")
        self.capacity = int(capacity)
        self._ticks: list[Tick | None] = [None] * self.capacity
        self._numbers = np.full(self.capacity, -1, dtype=np.int64)   # tick number held in each slot
        self._times = np.full(self.capacity, np.nan)
        self._series: dict[tuple[str, str], np.ndarray] = {}
        self._dims: dict[tuple[str, str], int] = {}
        self._tick_series: set[tuple[str, str]] = set()     # keys that came from Tick.series
        self.count = 0          # ticks appended in total
        self.newest_tick = -1
        self._version = 0       # changes whenever the held ticks do (the window slots cache's key)
        self._slot_cache: dict = {}
        self._oldest = (-1, -1)   # (version, oldest tick held): panels ask every frame, ticks come less often

    # -- appending ---------------------------------------------------------------------------
    def append(self, tick: Tick) -> None:
        """Add the next tick. Tick numbers must increase (gaps are allowed)."""
        if tick.tick <= self.newest_tick:
            raise ValueError(f"tick {tick.tick} is not newer than the newest tick {self.newest_tick}")
        slot = tick.tick % self.capacity
        # a gap leaves stale slots behind: clear the ones skipped over
        if self.newest_tick >= 0 and tick.tick - self.newest_tick > 1:
            for t in range(self.newest_tick + 1, min(tick.tick, self.newest_tick + 1 + self.capacity)):
                s = t % self.capacity
                self._ticks[s] = None
                self._numbers[s] = -1
        self._ticks[slot] = tick
        self._numbers[slot] = tick.tick
        self._times[slot] = tick.time_s
        for name, snap in tick.snapshots.items():
            for key, get in SERIES.items():
                self._store(name, key, slot, get(snap))
        for k in self._tick_series - tick.series.keys():
            self._series[k][slot] = np.nan
        for (name, key), value in tick.series.items():
            self._store(name, key, slot, value)
            self._tick_series.add((name, key))
        self.count += 1
        self.newest_tick = tick.tick
        self._version += 1

    def _store(self, controller: str, key: str, slot: int, value) -> None:
        k = (controller, key)
        arr = self._series.get(k)
        if value is None:
            if arr is not None:
                arr[slot] = np.nan
            return
        if arr is None:
            dims = int(np.size(value)) if np.ndim(value) else 0
            shape = (self.capacity,) if dims == 0 else (self.capacity, dims)
            arr = self._series[k] = np.full(shape, np.nan, dtype=np.float64)
            self._dims[k] = dims
        arr[slot] = value

    def clear(self) -> None:
        self.__init__(self.capacity)

    # -- addressing --------------------------------------------------------------------------
    def __len__(self) -> int:
        return int(np.count_nonzero(self._numbers >= 0))

    @property
    def oldest_tick(self) -> int:
        """The oldest tick still held (-1 when empty)."""
        if self.newest_tick < 0:
            return -1
        version, oldest = self._oldest
        if version != self._version:
            held = self._numbers[self._numbers >= 0]
            oldest = int(held.min()) if len(held) else -1
            self._oldest = (self._version, oldest)
        return oldest

    def contains(self, tick: int) -> bool:
        return tick >= 0 and self._numbers[tick % self.capacity] == tick

    def get(self, tick: int) -> Tick | None:
        """The tick with that number, or None when it is not (or no longer) held."""
        if not self.contains(tick):
            return None
        return self._ticks[tick % self.capacity]

    def latest(self) -> Tick | None:
        return self.get(self.newest_tick) if self.newest_tick >= 0 else None

    def clamp(self, tick: int) -> int:
        """The nearest held tick number to ``tick`` (-1 when empty)."""
        if self.newest_tick < 0:
            return -1
        return int(min(max(tick, self.oldest_tick), self.newest_tick))

    # -- series ------------------------------------------------------------------------------
    def has_series(self, controller: str, key: str) -> bool:
        return (controller, key) in self._series

    def window(self, controller: str, key: str, end_tick: int, n: int, out: np.ndarray | None = None) -> np.ndarray:
        """Values of a series for the ``n`` ticks ending at ``end_tick`` (inclusive), oldest first.

        Ticks not held (before the oldest, after the newest, or skipped) are NaN. Shape ``(n,)`` or
        ``(n, dims)``; a series never seen is all NaN with shape ``(n,)``.
        """
        slots, missing = self._window_slots(end_tick, n)
        arr = self._series.get((controller, key))
        if arr is None:
            res = np.full(n, np.nan) if out is None else out
            res[...] = np.nan
            return res
        res = np.take(arr, slots, axis=0, out=out)
        if missing is not None:
            res[missing] = np.nan
        return res

    def _window_slots(self, end_tick: int, n: int):
        """(ring slots of the ``n`` ticks ending at ``end_tick``, mask of those not held or None when all
        are), kept until the held ticks change: the panels ask for many series of the same window."""
        key = (end_tick, n)
        hit = self._slot_cache.get(key)
        if hit is not None and hit[0] == self._version:
            return hit[1], hit[2]
        ticks = np.arange(end_tick - n + 1, end_tick + 1)
        slots = ticks % self.capacity
        held = (ticks >= 0) & (self._numbers[slots] == ticks)
        missing = None if held.all() else ~held
        if len(self._slot_cache) > 16:
            self._slot_cache.clear()
        self._slot_cache[key] = (self._version, slots, missing)
        return slots, missing

    def times(self, end_tick: int, n: int) -> np.ndarray:
        ticks = np.arange(end_tick - n + 1, end_tick + 1)
        slots = ticks % self.capacity
        held = (ticks >= 0) & (self._numbers[slots] == ticks)
        return np.where(held, self._times[slots], np.nan)

    def ticks_between(self, first: int, last: int) -> list[Tick]:
        """Held ticks with first <= number <= last, oldest first."""
        return [t for t in (self.get(i) for i in range(max(first, 0), last + 1)) if t is not None]


def search_agreement(history: History, controller: str, end_tick: int, n: int,
                     tolerance_frames: int = 0, chosen: str = "projected_frame") -> tuple[float, int]:
    """Fraction of the searches in the window where the frame the projector chose (the database
    frame nearest its output, series ``chosen``) is within ``tolerance_frames`` of the exact nearest
    neighbour (``nn_frame``), and how many searches there were. (nan, 0) without searches."""
    return agreement(history.window(controller, "searched", end_tick, n),
                     history.window(controller, "nn_frame", end_tick, n),
                     history.window(controller, chosen, end_tick, n), tolerance_frames)


def agreement(searched: np.ndarray, nn: np.ndarray, got: np.ndarray, tolerance_frames: int = 0) -> tuple[float, int]:
    """:func:`search_agreement` of windows already gathered (``searched``, ``nn_frame`` and the chosen frame)."""
    return masks_agreement(*search_masks(searched, nn, got, tolerance_frames))


def search_masks(searched, nn, got, tolerance_frames: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Per tick: was it a search (a finite nearest neighbour and a finite chosen frame), and did the chosen
    frame agree with the nearest neighbour within ``tolerance_frames`` frames."""
    nn, got = np.asarray(nn), np.asarray(got)
    with np.errstate(invalid="ignore"):   # rows with a NaN or inf are not searches (s is False there)
        s = (np.asarray(searched) > 0.5) & np.isfinite(nn) & (nn >= 0) & np.isfinite(got)
        agree = s & (np.abs(got - nn) <= tolerance_frames)
    return s, agree


def masks_agreement(searched: np.ndarray, agreed: np.ndarray) -> tuple[float, int]:
    """(fraction of the searches that agreed, how many searches) of :func:`search_masks`; (nan, 0) without
    searches."""
    k = int(searched.sum())
    return (int(agreed.sum()) / k, k) if k else (float("nan"), 0)
