"""Any tick of a session, at once: a replay that keeps controller-state checkpoints as it goes.

:class:`SessionSeeker` steps a session's controllers (built as :class:`lmm.session.player.SessionPlayer`
builds them) and keeps, every ``every`` ticks it passes, a checkpoint: each controller's state
(:class:`lmm.session.checkpoint.ControllerState`, about 60-100 KB), the tuning and the next event. Showing
tick ``t`` restores the nearest checkpoint at or before ``t`` (unless stepping on from where it is is
shorter) and steps to ``t``: at most ``every - 1`` ticks. The poses are the recorded ones bit for bit (a
test compares them with the session's fingerprints). The studio's ``--open`` uses it; so can a script.

A branch (:meth:`SessionSeeker.branched`, the studio's *Branch here*) is a seeker of its own controllers that
starts from the state of the nearest checkpoint at or before the branch tick this seeker has (the arms are
the same until then; :meth:`lmm.session.checkpoint.ControllerState.transplant`), not from the session's
start: at the end of a 10-minute session that was a replay of the whole session.
"""
from __future__ import annotations

import bisect
from contextlib import contextmanager

from lmm.runner import step_controllers
from lmm.session.checkpoint import ControllerState
from lmm.session.player import apply_due_events


class SessionSeeker:
    def __init__(self, session, db, features, *, every: int | None = None, weights: dict | None = None,
                 debug_comparison: bool = False, branch: dict | None = None, from_tick: int = 0):
        from lmm.session.player import SessionPlayer

        player = SessionPlayer(session, db, features, weights=weights, debug_comparison=debug_comparison)
        self.session, self.controllers, self.tuning = session, player.controllers, player.tuning
        self.db, self.features, self.weights, self.debug_comparison = db, features, weights, debug_comparison
        self.dt = session.dt
        self.branch, self.from_tick = branch, int(from_tick)     # arm B of ``ab`` (SessionPlayer's meaning)
        self.every = int(every) if every else max(1, int(round(session.fps)))   # one a second
        changes = list(session.inputs())
        self._input_ticks = [t for t, _ in changes]
        self._inputs = [inp for _, inp in changes]
        self._events = session.events
        self._next = 0                  # the next event to apply
        self.tick = 0                   # the next tick to step
        self.checkpoints: dict[int, tuple] = {}
        self.stepped = 0                # ticks stepped in all (what seeking cost)
        self._keep()

    def branched(self, branch: dict, from_tick: int) -> "SessionSeeker":
        """Arm B: ``branch`` set at ``from_tick`` (:class:`lmm.session.player.SessionPlayer`'s meaning), its own
        controllers given this seeker's state at its nearest checkpoint at or before ``from_tick``."""
        b = SessionSeeker(self.session, self.db, self.features, every=self.every, weights=self.weights,
                          debug_comparison=self.debug_comparison, branch=branch, from_tick=from_tick)
        start = max(t for t in self.checkpoints if t <= b.from_tick)
        tuning, states, next_event = self.checkpoints[start]
        for (name, c), state in zip(b.controllers.items(), states):
            state.transplant(c)
        for field, value in tuning.items():      # after the states: the controllers re-derive what differs
            setattr(b.tuning, field, value)
        b._next, b.tick = next_event, start
        b._keep()
        return b

    @property
    def ticks(self) -> int:
        return self.session.ticks

    def input_at(self, tick: int):
        """The input tick ``tick`` is stepped with."""
        return self._inputs[bisect.bisect_right(self._input_ticks, tick) - 1]

    def step(self):
        """Step the next tick: ``(poses, snapshots)`` by controller name."""
        tick = self.tick
        self._next = apply_due_events(self._events, self._next, tick, self.tuning, self.controllers,
                                      self.branch, self.from_tick)
        poses, snaps, _ = step_controllers(self.controllers, self.input_at(tick), self.dt)
        self.tick += 1
        self.stepped += 1
        if self.tick % self.every == 0 and self.tick not in self.checkpoints:
            self._keep()
        return poses, snaps

    def seek(self, tick: int):
        """``(poses, snapshots)`` of tick ``tick`` (``0 <= tick < ticks``), re-simulated from the nearest
        checkpoint."""
        if not 0 <= tick < self.ticks:
            raise IndexError(f"tick {tick} is outside the session's {self.ticks} ticks")
        self.go_before(tick)
        out = None
        while self.tick <= tick:
            out = self.step()
        return out

    def go_before(self, tick: int) -> None:
        """Make the next tick stepped the nearest one at or before ``tick`` that is cheap to reach: where
        the seeker is, when that is between the nearest checkpoint and ``tick``, else that checkpoint."""
        start = max(c for c in self.checkpoints if c <= tick)
        if not start <= self.tick <= tick:
            self._restore(start)

    @contextmanager
    def before(self, tick: int):
        """For the body of a ``with``: the controllers as they were just before stepping tick ``tick`` (what
        its search saw: :mod:`lmm.session.why_not` asks them), with the tuning then; the seeker is put back
        where it was afterwards, so a reader of its ticks (the studio's review) never notices."""
        if not 0 <= tick < self.ticks:
            raise IndexError(f"tick {tick} is outside the session's {self.ticks} ticks")
        here = (self.tuning.to_dict(), tuple(ControllerState(c) for c in self.controllers.values()), self._next,
                self.tick)
        try:
            self.go_before(tick)
            while self.tick < tick:
                self.step()
            yield self.controllers
        finally:
            self._put(*here)

    def fill(self, progress=None) -> None:
        """Step through the whole session once, keeping every checkpoint (``progress(tick)`` now and then)."""
        last = max(self.checkpoints)
        if self.tick != last:
            self._restore(last)
        while self.tick < self.ticks:
            self.step()
            if progress is not None and self.tick % (10 * self.every) == 0:
                progress(self.tick)

    def checkpoint_bytes(self) -> int:
        return sum(sum(s.nbytes for s in states) for _, states, _ in self.checkpoints.values())

    def _keep(self) -> None:
        states = tuple(ControllerState(c) for c in self.controllers.values())
        self.checkpoints[self.tick] = (self.tuning.to_dict(), states, self._next)

    def _restore(self, tick: int) -> None:
        self._put(*self.checkpoints[tick], tick)

    def _put(self, tuning: dict, states: tuple, next_event: int, tick: int) -> None:
        for c, state in zip(self.controllers.values(), states):
            state.restore(c)
        # then the tuning: the fields that differ are announced, so a controller re-derives what it keeps
        # of them (weighted features, search indexes: kept by reference, written in place when weights change)
        for name, value in tuning.items():
            setattr(self.tuning, name, value)
        self._next, self.tick = next_event, tick
