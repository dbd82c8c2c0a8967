"""Driving a run from a session: recording one (:class:`SessionRecorder`, the hooks of
:func:`lmm.runner.run_headless`) and playing one back (:class:`SessionPlayer`, one tick at a time).

A replay rebuilds the controllers the session names on the same database, starts them as the session
did, and steps them through :func:`lmm.runner.step_controllers` with the recorded input and events: the
runtime is deterministic, so every pose comes out bit for bit as recorded, which the fingerprints prove.
A *branch* takes another tuning from tick N on (the recorded tuning changes from then on are not applied;
actions are): its fingerprints before N must match, after N they need not.
"""
from __future__ import annotations

from lmm.runner import step_controllers
from lmm.session.actions import Event, apply_event
from lmm.session.schema import SessionError, pose_fingerprint


class SessionRecorder:
    """The session side of ``run``: ``events`` (checked :class:`Event` s) act before their tick, and
    ``writer`` (a :class:`lmm.session.writer.SessionWriter`, or None) stores the input, the events (tuning
    changes through its subscription, actions here) and the fingerprints. Pass :meth:`before_step` and
    :meth:`after_step` to :func:`lmm.runner.run_headless`."""

    def __init__(self, tuning, controllers: dict, events: list[Event] = (), writer=None):
        self.tuning, self.controllers, self.writer = tuning, controllers, writer
        self._events = list(events)
        self._next = 0
        self.last_poses = None

    def before_step(self, tick: int, inp) -> None:
        if self.writer is not None:
            self.writer.begin_tick(tick, inp)
        while self._next < len(self._events) and self._events[self._next].tick <= tick:
            event = self._events[self._next]
            self._next += 1
            apply_event(event, self.tuning, self.controllers)
            if self.writer is not None and event.kind != "tuning":   # tuning changes arrive as events
                self.writer.event(event.kind, event.payload)

    def after_step(self, tick: int, poses: dict) -> None:
        self.last_poses = poses
        if self.writer is not None:
            self.writer.end_tick(tick, poses)

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close(self.last_poses)


def apply_due_events(events, next_event: int, tick: int, tuning, controllers, branch=None,
                     from_tick: int = 0) -> int:
    """Apply the recorded events due before stepping ``tick`` from ``events[next_event]`` on; returns the
    next event's index. A branch (a tuning preset dict) is set at ``from_tick`` on top of the tuning then,
    and the recorded tuning changes from then on are left out (its actions are kept)."""
    branched = branch is not None and tick >= from_tick
    if branch is not None and tick == from_tick:
        from lmm.tuning import Tuning
        tuning.assign(Tuning.from_dict(branch, base=tuning))
    while next_event < len(events) and events[next_event].tick <= tick:
        event = events[next_event]
        next_event += 1
        if not (branched and event.kind == "tuning"):
            apply_event(event, tuning, controllers)
    return next_event


class SessionPlayer:
    """Steps a session's controllers tick by tick (:meth:`step`), checking each recorded fingerprint.

    ``branch``: a tuning preset (a dict, checked by :meth:`lmm.tuning.Tuning.from_preset`) whose fields are
    set at tick ``from_tick`` on top of the tuning then, instead of the recorded changes that follow;
    ``debug_comparison``: also run LMM's exact nearest-neighbour search (``trace``), which never changes
    the motion; ``weights``: controller name -> networks file (default: the recorded path)."""

    def __init__(self, session, db, features, *, branch=None, from_tick: int = 0, debug_comparison: bool = False,
                 weights: dict | None = None):
        from lmm.factory import make_controller
        from lmm.tuning import TuningError

        self.session = session
        self.dt = session.dt
        try:
            self.tuning = session.start_tuning(channels=[ch.name for ch in features.layout])
        except TuningError as e:
            raise SessionError(f"{session.path}: meta 'tuning': {e}") from None
        self.controllers = {name: make_controller(kind, db, features, self.tuning,
                                                  (weights or {}).get(name) or recorded or None,
                                                  debug_comparison=debug_comparison)
                            for name, (kind, recorded, _) in session.controllers.items()}
        for c in self.controllers.values():
            c.reset(**session.meta["start"].get("reset", {}))
        self.branch, self.from_tick = branch, int(from_tick)
        self.tick = 0
        self._inputs = session.inputs()
        self._pending = next(self._inputs, None)
        self.input = None
        self._events = session.events
        self._next = 0
        self.checked = 0                 # fingerprints compared
        self.mismatches: list[tuple[int, str]] = []   # (tick, controller) whose pose differs from the record

    @property
    def done(self) -> bool:
        return self.tick >= self.session.ticks

    def step(self):
        """Step the next tick: ``(poses, snapshots)`` keyed by controller name."""
        tick = self.tick
        self._next = apply_due_events(self._events, self._next, tick, self.tuning, self.controllers,
                                      self.branch, self.from_tick)
        while self._pending is not None and self._pending[0] <= tick:
            self.input = self._pending[1]
            self._pending = next(self._inputs, None)
        poses, snaps, _ = step_controllers(self.controllers, self.input, self.dt)
        for name, pose in poses.items():
            recorded = self.session.fingerprints.get((tick, name))
            if recorded is not None:
                self.checked += 1
                if pose_fingerprint(pose) != recorded:
                    self.mismatches.append((tick, name))
        self.tick += 1
        return poses, snaps

    def unexpected_mismatches(self) -> list[tuple[int, str]]:
        """Mismatches that prove the replay wrong: all of them, or a branch's before its tick."""
        if self.branch is None:
            return list(self.mismatches)
        return [(t, n) for t, n in self.mismatches if t < self.from_tick]
