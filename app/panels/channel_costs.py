"""The per-channel cost timeline, the "channel costs" tab of the Nearest Neighbour vs Projector panel
(:mod:`.search`): the inspected controller's played pose against each tick's query, its cost stacked by
feature channel (one band per channel, the top the whole cost), the ticks its pose jumped marked along the
top and the shown tick as a vertical line.

In a reopened session it covers every tick: the session's :class:`lmm.session.cost_timeline.CostTimeline`,
worked out once in the background when the session opens (:meth:`app.review.SessionHistory.cost_timeline`;
until then the tab says how far it is), stacked and thinned to :data:`MAX_POINTS` once per controller
(the largest cost of each run of ticks kept). Live, it covers the rewind history, worked out from the
snapshots only while the tab is shown, each tick once: about 1 ms a frame for 20 s of history (25 ms the
first time the tab is shown).
"""
from __future__ import annotations

import numpy as np

from lmm.session.cost_timeline import peak_rows, stacked

from .common import TextCache, short_channel_name

#: points drawn per band (a plot is at most a few thousand pixels wide)
MAX_POINTS = 1500
#: transition marks drawn (thinned evenly beyond this; the state keeps every one)
MAX_MARKS = 3000
#: one colour per channel band (RGB 0..1), in the features' order
PALETTE = ((0.90, 0.45, 0.35), (0.95, 0.65, 0.30), (0.35, 0.70, 0.90), (0.30, 0.50, 0.95),
           (0.75, 0.55, 0.95), (0.45, 0.85, 0.55), (0.30, 0.80, 0.80), (0.85, 0.45, 0.75))


class ChannelCostPlot:
    """Built into the panel's tab; ``prepare`` may run on the tick worker (reads only), ``update`` on the
    GUI thread keeps the drawn series of a session's timeline (made once per timeline and controller)."""

    def __init__(self, dpg, theme, channel_names, features_of, dt: float, on_pick=None):
        self.dpg, self.theme, self.dt = dpg, theme, float(dt)
        self.on_pick = on_pick               # on_pick(tick): a click on the plot asks to show that tick
        self._span = (0, -1)                 # the first and last tick the plot covers
        self.picked: int | None = None       # the tick the last click asked for
        self.channels = list(channel_names)
        self.features_of = features_of       # controller -> the features it searches (live costs)
        self._drawn_for = None               # (timeline id, controller) of the session series drawn
        self._bands = None                   # that timeline's thinned (x, stacked rows)
        self._shown_key = None               # what the bands hold now
        self._memo: dict = {}                # (controller, tick number) -> (the Tick, its cost row, jumped)
        self.text = TextCache(dpg)
        self.last: dict = {}

    def build(self) -> None:
        dpg = self.dpg
        dpg.add_text("", tag="chc_status", wrap=0)
        with dpg.plot(tag="chc_plot", height=-1, width=-1, no_menus=True, no_mouse_pos=True):
            dpg.add_plot_legend(location=dpg.mvPlot_Location_North, horizontal=True, outside=True)
            dpg.add_plot_axis(dpg.mvXAxis, tag="chc_x", label="seconds", auto_fit=True)
            with dpg.plot_axis(dpg.mvYAxis, tag="chc_y", label="cost"):
                z = [0.0]
                for c, name in enumerate(self.channels):
                    dpg.add_shade_series(z, z, y2=z, tag=f"chc_band_{c}", label=short_channel_name(name))
                dpg.add_scatter_series(z, z, tag="chc_transitions", label="transitions")
                dpg.add_inf_line_series(z, tag="chc_tick", label="shown tick")
        with dpg.item_handler_registry(tag="chc_handlers"):
            dpg.add_item_clicked_handler(callback=lambda: self.pick(dpg.get_plot_mouse_pos()[0]))
        dpg.bind_item_handler_registry("chc_plot", "chc_handlers")
        for c in range(len(self.channels)):
            self.theme.series(f"chc_band_{c}", PALETTE[c % len(PALETTE)])
        self.theme.series("chc_transitions", (0.95, 0.95, 0.95), marker=True, marker_size=2.0)
        self.theme.series("chc_tick", (1.0, 0.86, 0.35), weight=2.0)

    def prepare(self, view, shown: bool) -> dict:
        """Where the numbers come from and the shown tick's row; live (and only while ``shown``), the
        stacked costs of the rewind history up to the shown tick."""
        held = {} if view.tick is None else view.tick.snapshots
        name = view.inspected if view.inspected in held else next(iter(held), None)
        tick = view.tick_number
        timeline, status = getattr(view.history, "cost_timeline", (None, None))
        out = {"controller": name, "tick": tick, "status": status or "", "source": "", "row": None}
        if status is not None:                                   # a reopened session
            out["source"] = "session"
            if timeline is not None and name in timeline.costs:
                costs = timeline.costs[name]
                out["timeline"] = timeline
                out["row"] = costs[tick - 1] if 1 <= tick <= len(costs) else None
            return out
        if not shown or name is None or view.tick is None:
            return out
        held = self._history_rows(view.history, name, tick)
        if held is None:
            return out
        numbers, times, costs, jumped = held
        out.update(source="history", first=int(numbers[0]), x=times, stack=stacked(costs),
                   transitions=numbers[jumped], row=costs[-1] if numbers[-1] == tick else None)
        return out

    def _history_rows(self, history, name: str, last: int):
        """``(tick numbers, times, channel costs (n, C), transitioned)`` of the held ticks of ``name`` up to
        ``last`` (None without any). Each tick's row is worked out once, kept by the tick it is of (a memo:
        the same numbers every time, only the ticks that came since cost anything)."""
        ticks = [t for t in history.ticks_between(history.oldest_tick, last) if name in t.snapshots]
        if not ticks:
            return None
        memo = self._memo
        new = [t for t in ticks if memo.get((name, t.tick), (None,))[0] is not t]
        if new:
            snaps = [t.snapshots[name] for t in new]
            costs = self.features_of(name).channel_costs(np.stack([s.query for s in snaps]),
                                                         np.stack([s.current_features for s in snaps]))
            for t, snap, row in zip(new, snaps, costs):
                memo[(name, t.tick)] = (t, row, bool(snap.transitioned))
            if len(memo) > 3 * len(ticks) + 600:                 # ticks gone from the history
                held = {(name, t.tick) for t in ticks}
                self._memo = memo = {k: v for k, v in memo.items() if k in held}
        rows = [memo[(name, t.tick)] for t in ticks]
        return (np.array([t.tick for t in ticks]), np.array([t.time_s for t in ticks]),
                np.array([r[1] for r in rows]), np.array([r[2] for r in rows]))

    def pick(self, x_s: float) -> None:
        """A click on the plot at ``x_s`` seconds: show the nearest tick it covers."""
        first, last = self._span
        if self.on_pick is not None and last >= first:
            tick = tick_at(x_s, self.dt, first, last)
            self.picked = tick
            self.on_pick(tick)

    def update(self, view, p: dict, shown: bool) -> None:
        """Show ``p`` (:meth:`prepare`'s); the bands are handed to dearpygui only while ``shown`` and when
        they changed (a session's: once per timeline and controller)."""
        dpg = self.dpg
        if p["source"] == "session" and "timeline" in p:
            key, (x, rows, jumps, first, count) = (id(p["timeline"]), p["controller"]), self._session_series(
                p["timeline"], p["controller"])
        elif p["source"] == "history":
            ok = np.isfinite(p["stack"][:, -1])
            idx = peak_rows(p["stack"][:, -1], MAX_POINTS)
            idx = idx[ok[idx]]
            key, x, rows, jumps = id(p), p["x"][idx], p["stack"][idx], p["transitions"]
            first, count = p["first"], int(np.count_nonzero(ok))
        else:
            key, x, rows, jumps, first, count = None, np.zeros(1), np.zeros((1, len(self.channels) + 1)), \
                np.zeros(0, int), 0, 0
        if shown and key != self._shown_key:
            self._shown_key = key
            for c in range(len(self.channels)):
                dpg.set_value(f"chc_band_{c}", [x.tolist(), rows[:, c + 1].tolist(), rows[:, c].tolist(), [], []])
            # the cost axis ends above the 99th percentile: a few spikes (a forced search far from the
            # playing pose) would flatten every other tick's bands
            top = rows[:, -1][np.isfinite(rows[:, -1])]
            top = float(np.percentile(top, 99)) * 1.25 if len(top) else 1.0
            dpg.set_axis_limits("chc_y", 0.0, max(top, 1e-6))
            marks = jumps if len(jumps) <= MAX_MARKS else jumps[np.linspace(0, len(jumps) - 1, MAX_MARKS).astype(int)]
            dpg.set_value("chc_transitions", [(marks * self.dt).tolist() or [0.0], [0.95 * top] * max(len(marks), 1)])
            dpg.configure_item("chc_transitions", show=len(marks) > 0)
        if shown:
            dpg.set_value("chc_tick", [[view.tick_number * self.dt]])
        self._span = (first, first + count - 1)
        row = p["row"]
        where = {"session": "the whole session", "history": "the rewind history"}.get(p["source"], "")
        status = p["status"] or (f"{p['controller']}: played pose vs query, cost by channel over {where} "
                                 f"(ticks {first}-{first + count - 1}); {len(jumps)} transitions"
                                 if count else "no channel costs to show")
        if row is not None:
            status += f"\ntick {p['tick']}: total {float(np.sum(row)):.3f} = " + " + ".join(
                f"{short_channel_name(n)} {v:.3f}" for n, v in zip(self.channels, row))
        if shown:
            self.text.set("chc_status", status)
        self.last = {"source": p["source"], "controller": p["controller"], "status": status, "first_tick": first,
                     "ticks": count, "channels": self.channels, "tick": p["tick"], "drawn_points": int(len(x)),
                     "picked": self.picked,
                     "row": None if row is None else [float(v) for v in row],
                     "transitions": [int(t) for t in jumps]}

    def _session_series(self, timeline, name):
        """A session timeline's thinned, stacked series for ``name`` (made once), its transition ticks (the
        history's numbers), its first tick and how many ticks have costs."""
        key = (id(timeline), name)
        if self._drawn_for != key:
            stack = stacked(timeline.costs[name])
            ok = np.isfinite(stack[:, -1])
            idx = peak_rows(stack[:, -1], MAX_POINTS)
            idx = idx[ok[idx]]
            self._bands = ((idx + 1) * timeline.dt, stack[idx], np.flatnonzero(timeline.transitioned[name]) + 1,
                           int(np.count_nonzero(ok)))
            self._drawn_for = key
        x, rows, jumps, count = self._bands
        return x, rows, jumps, 1, count


def tick_at(x_s: float, dt: float, first: int, last: int) -> int:
    """The tick shown at ``x_s`` seconds of the plot (tick ``n`` at ``n * dt``), kept within ``first..last``."""
    return int(min(max(round(x_s / dt), first), last))
