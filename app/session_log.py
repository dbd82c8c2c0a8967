"""The studio's session log: what makes a studio recording replayable bit for bit (:mod:`lmm.session`).

A recording starts mid-session: the characters are wherever the user has walked them since the last reset,
their springs, inertialization and search timers in the middle of something. Rather than serialise every
controller's inner state (large, and one more format to keep exact), the studio keeps, from its last reset
on, what reproduces that state: the tuning at the reset, the input of every tick (changes only, a few
bytes a tick), every tuning change and action, and a pose fingerprint a second. The runtime is
deterministic, so a replay from the reset reaches the recording's first tick in exactly the recorded state.

When a recording starts at tick ``T`` of the log, a :class:`lmm.session.writer.SessionWriter` is made
beside its BVH (``take.lmmsession``) with ticks ``0 .. T-1`` written at once (meta ``recording.from_tick
= T``: ``lmm-studio replay take.lmmsession --record R.bvh`` records from there, equal to the studio's
BVH byte for byte); it then stores each tick as it is stepped until the recording stops. A reset during a
recording is a ``reset`` event (the replay resets its controllers at that tick, as the studio did); new
LMM weights end the session file (the recording goes on), since a session names one set of networks.
Motion-changing commands (reset, replayed input, follow) are kept as ``command`` events for the reader.

Memory: the input changes are kept in flat arrays (64 bytes a change: live gamepad input changing every
tick is 14 MiB an hour); a reset starts the log afresh.
"""
from __future__ import annotations

from array import array
from pathlib import Path

from lmm.data.inputs import InputState
from lmm.session.schema import pose_fingerprint, ticks_per_second
from lmm.session.writer import SessionWriter, tuning_payload

#: commands kept in a session as ``command`` events (they act through a reset, stored as its own event)
RECORDED_COMMANDS = ("reset_characters", "open_input", "live_input", "follow", "open")


def _plain_args(args: dict) -> dict:
    """A command's arguments as JSON holds them (anything else as its text)."""
    out = {}
    for k, v in args.items():
        if isinstance(v, tuple):
            v = list(v)
        ok = v is None or isinstance(v, (bool, int, str)) or (isinstance(v, float) and v == v and abs(v) < 1e300)
        ok = ok or (isinstance(v, list) and all(isinstance(x, (str, int, float, bool)) for x in v))
        out[str(k)] = v if ok else str(v)[:200]
    return out


class SessionLog:
    """Everything since the last reset of ``session`` (an :class:`app.session.Session`), and the session
    file of the recording in progress. ``Session.step`` calls :meth:`before_step` / :meth:`after_step`
    around each tick, ``Session.reset`` :meth:`reset`; tuning changes arrive through ``tuning.events``."""

    def __init__(self, session):
        self.session = session
        self.every = ticks_per_second(session.dt)
        self.writer: SessionWriter | None = None
        self.path: Path | None = None
        self.ended = ""              # one line: why the session file ended before the recording did
        self.restart()
        session.tuning.events.connect(self._on_tuning_change)

    def restart(self) -> None:
        """Start afresh: the controllers as they are now (just reset), tick 0."""
        s = self.session
        self.tuning_at_start = s.tuning.to_dict()
        self.controllers = dict(s.controllers)
        self.input_name = s.input_log.name if s.input_log is not None else "live"
        self.tick = 0
        self._input_ticks = array("q")
        self._inputs = array("d")              # 7 numbers a change (walk and strafe as 0.0 / 1.0)
        self._last_input = None
        self.events: list[tuple[int, str, dict]] = []
        self.fingerprints: list[tuple[int, str, str]] = []

    # -- per tick (the tick worker's thread, or the caller's) -----------------------------------
    def before_step(self, inp: InputState) -> None:
        if self.writer is not None:
            self.writer.begin_tick(self.tick, inp)
        row = (inp.left_x, inp.left_y, inp.right_x, inp.right_y, float(bool(inp.walk)), float(bool(inp.strafe)),
               inp.camera_azimuth)
        if row != self._last_input:
            self._input_ticks.append(self.tick)
            self._inputs.extend(row)
            self._last_input = row

    def after_step(self, poses: dict) -> None:
        if self.writer is not None:
            self.writer.end_tick(self.tick, poses)
        if (self.tick + 1) % self.every == 0:       # the writer's own rhythm: one a second
            self.fingerprints.extend((self.tick, name, pose_fingerprint(p)) for name, p in poses.items())
        self.tick += 1

    def inputs(self):
        """``(tick, InputState)`` of each input change kept."""
        v = self._inputs
        for i, tick in enumerate(self._input_ticks):
            lx, ly, rx, ry, walk, strafe, azimuth = v[7 * i: 7 * i + 7]
            yield tick, InputState(lx, ly, rx, ry, walk > 0.5, strafe > 0.5, azimuth)

    # -- changes between ticks (the GUI thread) ------------------------------------------------------
    def _on_tuning_change(self, change) -> None:
        self.events.append((self.tick, "tuning", tuning_payload(change)))   # (a writer subscribes itself)

    def _event(self, kind: str, payload: dict) -> None:
        if self.writer is not None:
            self.writer.event(kind, payload)
        self.events.append((self.tick, kind, payload))

    def command(self, run) -> None:
        """A :class:`app.command_registry.CommandRun`: kept when it is one of :data:`RECORDED_COMMANDS`."""
        if run.id in RECORDED_COMMANDS:
            self._event("command", {"id": run.id, "args": _plain_args(dict(run.kwargs, **{
                f"arg{i}": a for i, a in enumerate(run.args)}))})

    def reset(self) -> None:
        """The characters were reset: a ``reset`` event in the session being written, else a fresh log. Other
        controllers than the session's (new LMM weights) end the session file."""
        same = set(map(id, self.session.controllers.values())) == set(map(id, self.controllers.values()))
        if self.writer is not None and same:
            self._event("reset", {})
            return
        if self.writer is not None:
            self.ended = f"{self.path.name} ends at tick {self.tick}: the controllers changed (new weights)"
            self.close()
        self.restart()

    # -- the session file of a recording -----------------------------------------------------------
    def start_writing(self, path, manifest=None) -> Path:
        """Write the session to ``path`` from its start, then each tick as it comes (the recording's first
        tick is the next one). Raises ``OSError`` when the file cannot be made."""
        s = self.session
        self.close()
        self.ended = ""
        writer = SessionWriter(path, fps=1.0 / s.dt, db=s.db, manifest=manifest, controllers=self.controllers,
                               tuning=s.tuning, start={"input": f"studio ({self.input_name})", "seconds": None,
                                                       "reset": {}},
                               start_tuning=self.tuning_at_start, recording_from=self.tick)
        try:
            writer.write_past(self.inputs(), self.events, self.fingerprints, self.tick)
        except BaseException:
            writer.close()
            raise
        self.writer, self.path = writer, Path(path)
        return self.path

    def close(self, last_poses: dict | None = None) -> None:
        """Close the session file; the log goes on (a later recording's session holds this stretch too)."""
        writer, self.writer = self.writer, None
        if writer is not None:
            writer.close(last_poses)
