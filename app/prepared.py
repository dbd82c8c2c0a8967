"""The panels' numeric work for the next frame, done on the tick worker while dearpygui draws.

A live studio shows the newest tick. Right after stepping it, the tick worker calls ``prepare`` of the
panels that have one (the 3D view's characters, the latent maps, the search and speed plots...) with
the view the next frame will have. The next frame uses those results instead of working them out on
the GUI thread, but only when nothing they depend on changed in between. These are the displayed tick
(the same object), the frame number, what the view says (live, paused, the inspected controller,
problems) and each panel's own ``prepare_key`` (its settings). Any other frame (paused, scrubbed, a
setting changed, the first frame) works them out on the GUI thread, with the same function.

A frame that is not live (paused or scrubbed) keeps what it worked out, and the next such frame uses it
again while the displayed tick (the same object), the history's newest tick, the view and the panel's
``prepare_key`` are unchanged: a paused studio does not work the same numbers out every frame. Panels
whose ``prepare`` reads the frame number (``prepare_uses_frame``, e.g. a colour range that keeps
easing) work theirs out every frame.

``prepare`` must only read: the view, the history and the panel's settings. It makes no dearpygui or
GL call and changes nothing that ``update`` reads. ``LMM_STUDIO_CHECK_PREPARED=1`` (the GUI tests)
works every used result out again on the GUI thread and counts the ones that differ.
"""
from __future__ import annotations

import dataclasses
import os
from collections import Counter
from dataclasses import dataclass

import numpy as np


def view_key(view) -> tuple:
    """What a prepared result depends on in the view besides the tick and the frame number."""
    return (view.live, view.paused, view.inspected, tuple(sorted(view.problems.items())), view.latent_status)


@dataclass
class PreparedFrame:
    tick: object                  # the tick the results are for (identity is checked)
    frame: int
    key: tuple                    # view_key of the view they were made with
    parts: dict                   # panel key -> (its prepare_key, its result)


def same(a, b) -> bool:
    """Deep equality of prepared results: arrays element by element (NaN equal to NaN), dataclasses
    and objects by their fields, containers item by item."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        if not (isinstance(a, np.ndarray) and isinstance(b, np.ndarray)):
            return False
        if a.shape != b.shape or a.dtype != b.dtype:
            return False
        return bool(np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"))
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (a != a and b != b)
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if dataclasses.is_dataclass(a) or hasattr(a, "__dict__"):
        return type(a) is type(b) and same(vars(a), vars(b))
    return a == b


class Preparer:
    """Asks the tick worker to prepare the next frame, and hands each panel its result when valid."""

    def __init__(self, panels: dict):
        from app.panels.base import Panel

        # the panels that prepare anything (a subclass overriding Panel.prepare)
        self.panels = {k: p for k, p in panels.items() if type(p).prepare is not Panel.prepare}
        self.check = os.environ.get("LMM_STUDIO_CHECK_PREPARED", "") not in ("", "0")
        self.used: Counter = Counter()           # panel key -> frames it used a worker result
        self.inline: Counter = Counter()         # panel key -> frames it worked its own out
        self.mismatches: list = []               # (panel key, frame) whose worker result differed
        self.kept: Counter = Counter()           # panel key -> frames (not live) that used a kept result
        self._frame: PreparedFrame | None = None
        self._kept: dict = {}                    # panel key -> (tick, (newest tick, view_key, prepare_key), result)

    def job(self, view, shown: set, next_frame: int):
        """The function the worker calls with the newest tick, or None when the next frame will not show
        it (not live: paused or scrubbing)."""
        if not view.live or not self.panels or view.mode == "SESSION":   # a reopened session: not the worker's ticks
            return None
        panels = [(k, p, p.prepare_key(view)) for k, p in self.panels.items() if k in shown]
        key = view_key(view)

        def work(tick) -> PreparedFrame:
            v = dataclasses.replace(view, tick=tick, frame=next_frame)
            return PreparedFrame(tick, next_frame, key, {k: (pk, p.prepare(v)) for k, p, pk in panels})

        return work

    def receive(self, prepared: PreparedFrame | None):
        """Take the next frame's prepared results; returns the ones they replace (the caller may have
        them freed elsewhere: see ``TickWorker.submit``)."""
        old, self._frame = self._frame, prepared
        return old

    def result(self, key: str, view):
        """Panel ``key``'s prepared result for ``view``, or None when it has to work it out itself."""
        panel = self.panels.get(key)
        if panel is None:
            return None
        f = self._frame
        hit = None
        if (f is not None and f.tick is view.tick and f.frame == view.frame and key in f.parts
                and f.key == view_key(view)):
            pkey, data = f.parts[key]
            if pkey == panel.prepare_key(view):
                hit = data
        if hit is None:
            # a reopened session's history changes while its newest tick stays: nothing kept for it
            if view.live or panel.prepare_uses_frame or view.mode == "SESSION":
                self.inline[key] += 1
                return None
            return self._kept_result(key, panel, view)
        self.used[key] += 1
        if self.check and not same(hit, panel.prepare(view)):
            self.mismatches.append((key, int(view.frame)))
        return hit

    def _kept_result(self, key: str, panel, view):
        """A frame that is not live: the result kept from an earlier such frame of the same tick, view
        and settings, else a new one (kept for the next)."""
        ident = (view.history.newest_tick, view_key(view), panel.prepare_key(view))
        kept = self._kept.get(key)
        if kept is not None and kept[0] is view.tick and kept[1] == ident:
            self.kept[key] += 1
            if self.check and not same(kept[2], panel.prepare(view)):
                self.mismatches.append((key, int(view.frame)))
            return kept[2]
        self.inline[key] += 1
        data = panel.prepare(view)
        self._kept[key] = (view.tick, ident, data)
        return data

    def state(self) -> dict:
        return {"used": dict(self.used), "inline": dict(self.inline), "kept": dict(self.kept), "checked": self.check,
                "mismatches": [list(m) for m in self.mismatches]}
