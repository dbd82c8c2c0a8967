"""What every panel shares: the window registry (fixed ids, so layout files work), colours, number
formats and small dearpygui helpers. What a panel is and may touch: :mod:`app.panels.base`."""
from __future__ import annotations

import functools
import math

import numpy as np

# key -> (fixed item id, title). The ids key the windows in layout (.ini) files: never renumber.
WINDOWS: dict[str, tuple[int, str]] = {
    "viewport": (10001, "3D Viewport"),
    "features": (10002, "Feature Vectors"),
    "latent": (10003, "Latent Traces"),
    "search": (10004, "Nearest Neighbour vs Projector"),
    "candidates": (10005, "Search Candidates"),
    "tuning": (10006, "Tuning"),
    "stats": (10007, "Stats"),
    "timeline": (10008, "Timeline"),
    "recording": (10009, "Recording & Input"),
    "database": (10010, "Database"),
    "coverage": (10011, "Coverage"),
    "motion_search": (10012, "Motion Search"),
    "physics": (10013, "Physics"),
}


def window_tag(key: str) -> int:
    return WINDOWS[key][0]


def built_windows(dpg) -> list[str]:
    """Keys of the windows this studio has built (a registered window whose panel is not part of this
    build is left out of layouts, menus and backgrounds)."""
    return [k for k in WINDOWS if dpg.does_item_exist(window_tag(k))]


def window_alias(key: str) -> str:
    return f"win_{key}"


# character colours (RGB 0..1); plots use the same ones so a glance links a curve to a character
COLORS = {
    "mm": (0.96, 0.56, 0.16),
    "lmm": (0.22, 0.66, 1.00),
}
SHORT = {"mm": "MM", "lmm": "LMM"}
RAGDOLL_COLOR = (0.55, 0.78, 0.55)     # the simulated character: grey-green, neither MM's nor LMM's
QUERY_COLOR = (0.92, 0.92, 0.92)
GOOD = (0.35, 0.85, 0.45)
BAD = (0.95, 0.35, 0.30)


def rgb255(c, alpha: float = 1.0) -> tuple[int, int, int, int]:
    return (int(round(c[0] * 255)), int(round(c[1] * 255)), int(round(c[2] * 255)), int(round(alpha * 255)))


def lighter(c, t: float = 0.45):
    return tuple(float(x + (1.0 - x) * t) for x in c)


def darker(c, t: float = 0.35):
    return tuple(float(x * (1.0 - t)) for x in c)


def cost_color(t: float) -> tuple[int, int, int, int]:
    """Green (t=0, cheapest) -> yellow -> red (t=1, dearest), as RGBA 0..255 for table cells."""
    t = float(t)
    t = min(max(t, 0.0), 1.0) if math.isfinite(t) else 0.5     # plain floats: called per table cell
    if t < 0.5:
        r, g = 2.0 * t, 1.0
    else:
        r, g = 1.0, 2.0 * (1.0 - t)
    return (int(40 + 150 * r), int(40 + 130 * g), 50, 150)


def short_channel_name(name: str) -> str:
    """``left_foot_position`` -> ``L foot pos``; readable tick labels for narrow plots."""
    words = name.replace("trajectory", "traj").replace("position", "pos").replace("velocity", "vel") \
        .replace("direction", "dir").replace("left_", "L ").replace("right_", "R ").replace("_", " ")
    return words


def fmt_num(v, digits: int = 3) -> str:
    if v is None:
        return "-"
    try:
        f = float(v)
    except (TypeError, ValueError):
        return str(v)
    if not np.isfinite(f):
        return "-"
    return f"{f:.{digits}f}"


def fmt_bytes(n: float) -> str:
    n = float(n)
    for unit in ("B", "KB", "MB", "GB"):
        if abs(n) < 1024.0 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024.0
    return f"{n:.1f} GB"


def overlapping(rects: dict, tolerance: float = 3.0) -> set:
    """Keys of the rectangles ``(x0, y0, x1, y1)`` that overlap another by more than ``tolerance`` px
    in both directions (windows that merely touch do not count)."""
    keys = list(rects)
    out = set()
    for i, a in enumerate(keys):
        ra = rects[a]
        for b in keys[i + 1:]:
            rb = rects[b]
            if min(ra[2], rb[2]) - max(ra[0], rb[0]) > tolerance and min(ra[3], rb[3]) - max(ra[1], rb[1]) > tolerance:
                out.update((a, b))
    return out


@functools.lru_cache(maxsize=32)
def seconds_axis(n: int, dt: float) -> np.ndarray:
    """Times of the ``n`` ticks ending now, in seconds (the newest at 0): a plot's x values, shared
    by every caller (never write to it)."""
    return (np.arange(n) - (n - 1)) * dt


def decimate(x: np.ndarray, y: np.ndarray, max_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Every k-th point (the last one always kept) so a line series has at most ``max_points``:
    a plot a few hundred pixels wide shows no more, and each point costs raster time."""
    n = len(x)
    if n <= max_points:
        return x, y
    k = int(np.ceil(n / max_points))
    idx = np.arange(n - 1, -1, -k)[::-1]
    return x[idx], y[idx]


class TextCache:
    """Sets a dearpygui value, option or axis limit only when it changed: a panel whose data did not
    change makes no dearpygui call (set_value on text costs a string copy, configure_item a few us)."""

    def __init__(self, dpg):
        self.dpg = dpg
        self.values: dict = {}

    def set(self, item, value) -> None:
        if self.values.get(item) != value:
            self.values[item] = value
            self.dpg.set_value(item, value)

    def get(self, item, default=None):
        return self.values.get(item, default)

    def configure(self, item, **options) -> None:
        """``configure_item(item, **options)`` with only the options whose value changed (the item's
        options must be changed only through this cache)."""
        values = self.values
        changed = {k: v for k, v in options.items() if values.get((item, k), _UNSET) != v}
        if changed:
            for k, v in changed.items():
                values[(item, k)] = v
            self.dpg.configure_item(item, **changed)

    def axis_limits(self, axis, lo: float, hi: float) -> None:
        key = (axis, "limits")
        if self.values.get(key) != (lo, hi):
            self.values[key] = (lo, hi)
            self.dpg.set_axis_limits(axis, lo, hi)


_UNSET = object()
