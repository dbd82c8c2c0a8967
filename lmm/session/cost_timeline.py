"""The per-channel cost timeline of a whole session: at every tick, each controller's played pose against
the tick's query, its cost split by feature channel (the trace's ``cost_<channel>`` columns, computed the
same way: :mod:`lmm.session.trace`), and the ticks the played pose jumped (``transitioned``).

:func:`session_cost_timeline` replays the session once (:class:`lmm.session.player.SessionPlayer`), made to
run beside other readers of the same session and database (the studio runs it in a child process,
:mod:`app.cost_timeline_job`; a thread works too): it opens the file itself (a SQLite connection serves only
the thread that opened it) and its controllers search a copy of the features (the session's weight changes
rescale that copy, never the features the other readers share). It keeps 4 bytes per tick,
controller and channel, and one per tick and controller for the transitions: a 30-minute session of MM and
LMM on 7 channels is 3.2 MB.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

#: progress is reported (and a cancel seen) every this many ticks
REPORT_EVERY = 600


@dataclass
class CostTimeline:
    """Row ``t`` of each array is the session's tick ``t`` (the trace's ``tick``; the studio's history
    numbers it ``t + 1``: the pose after ``t + 1`` steps)."""
    channels: list[str]
    dt: float
    costs: dict[str, np.ndarray]           # controller -> (ticks, channels) float32
    transitioned: dict[str, np.ndarray]    # controller -> (ticks,) bool
    mismatches: int = 0                    # recorded fingerprints the replay did not reproduce

    @property
    def ticks(self) -> int:
        return len(next(iter(self.transitioned.values()), ()))

    def nbytes(self) -> int:
        return sum(a.nbytes for a in self.costs.values()) + sum(a.nbytes for a in self.transitioned.values())


def session_cost_timeline(path, db, features, *, weights: dict | None = None, report=None,
                          cancelled=None) -> CostTimeline | None:
    """Replay the session file at ``path`` on ``db`` and the channel layout of ``features``, and return its
    :class:`CostTimeline` (None when ``cancelled()`` said so). ``report(fraction)``: progress, now and then;
    ``weights``: controller name -> networks file (default: the recorded path)."""
    from lmm.session.player import SessionPlayer
    from lmm.session.reader import open_session

    own = replace(features, weights=features.weights.copy())     # normalised anew: a buffer of its own
    session = open_session(path)
    try:
        player = SessionPlayer(session, db, own, weights=weights)
        n, names = session.ticks, own.names
        costs = {c: np.full((n, len(names)), np.nan, np.float32) for c in player.controllers}
        jumps = {c: np.zeros(n, bool) for c in player.controllers}
        while not player.done:
            tick = player.tick
            _, snaps = player.step()
            for name, snap in snaps.items():
                costs[name][tick] = own.channel_costs(np.asarray(snap.query), np.asarray(snap.current_features))
                jumps[name][tick] = bool(snap.transitioned)
            if tick % REPORT_EVERY == 0:
                if cancelled is not None and cancelled():
                    return None
                if report is not None:
                    report(tick / max(n, 1))
        return CostTimeline(list(names), session.dt, costs, jumps, len(player.mismatches))
    finally:
        session.close()


def stacked(costs: np.ndarray) -> np.ndarray:
    """``(ticks, C)`` channel costs -> ``(ticks, C + 1)`` running sums from 0: channel ``c``'s band lies
    between columns ``c`` and ``c + 1``, the last column is the whole cost (NaN rows stay NaN)."""
    out = np.zeros((costs.shape[0], costs.shape[1] + 1), np.float64)
    np.cumsum(costs, axis=1, out=out[:, 1:])
    out[np.isnan(out[:, -1])] = np.nan
    return out


def peak_rows(total: np.ndarray, max_rows: int) -> np.ndarray:
    """Indices of about ``max_rows`` rows of ``total`` for drawing: in each run of ``k`` consecutive rows
    the one with the largest value (a spike stays visible at any zoom-out), the last row always kept."""
    n = len(total)
    if n <= max_rows:
        return np.arange(n)
    k = int(np.ceil(n / max_rows))
    m = n // k * k
    blocks = np.where(np.isnan(total[:m]), -np.inf, total[:m]).reshape(-1, k)
    idx = np.argmax(blocks, axis=1) + np.arange(0, m, k)
    return np.unique(np.append(idx, np.arange(m, n)[-1:] if m < n else n - 1))
