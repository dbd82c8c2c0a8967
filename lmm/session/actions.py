"""Session events: what each kind means, how one is checked and how it acts on a run.

An event is ``(tick, kind, payload)``; the session's ``events`` table and an ``--events`` file hold the same
thing (README, "Sessions"). Kinds:

* ``tuning``: ``{"field": NAME, "channel": NAME | null, "new": VALUE, "old": VALUE}``: one
  :class:`lmm.tuning.TuningChange` (``old`` may be left out in an events file; in a session it is what the
  tuning held, and a replay checks it);
* ``reset``: ``{"position": [x, y, z], "rotation": [w, x, y, z], "frame": N, "controllers": [NAME, ...]}``,
  every key optional: :meth:`lmm.controller.Controller.reset` of those controllers (default: all);
* ``teleport``: ``{"position": [x, y, z], "yaw_deg": DEG, "controllers": [...]}``: a reset at that place,
  facing ``yaw_deg`` about +Y;
* ``command``: ``{"id": ID, "args": {...}}``: a studio command that changes no motion (camera, pause...),
  kept for the record and skipped by a replay.

An event at tick ``i`` acts before tick ``i`` is stepped. Checking is separate from acting, so a session or
events file is refused whole, with one line naming the file and the event, before anything runs.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from lmm.session.schema import MAX_EVENTS, MAX_PAYLOAD_CHARS, MAX_POSITION_M, MAX_TICKS, SessionError
from lmm.tuning import Tuning, TuningError

KINDS = ("tuning", "reset", "teleport", "command")
#: the keys each kind's payload may hold
KEYS = {"tuning": ("field", "channel", "new", "old"), "reset": ("position", "rotation", "frame", "controllers"),
        "teleport": ("position", "yaw_deg", "controllers"), "command": ("id", "args")}
#: Largest events file read (bytes)
MAX_EVENTS_FILE_BYTES = 16 * 1024 * 1024


@dataclass(frozen=True)
class Event:
    tick: int
    kind: str
    payload: dict

    def payload_json(self) -> str:
        return json.dumps(self.payload, sort_keys=True, allow_nan=False)


def _numbers(value, n: int, what: str, limit: float) -> list[float]:
    if not (isinstance(value, list) and len(value) == n
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
        raise ValueError(f"{what}: expected a list of {n} numbers")
    out = [float(v) for v in value]
    if not all(math.isfinite(v) and abs(v) <= limit for v in out):
        raise ValueError(f"{what}: numbers must be finite and within +-{limit:g}")
    return out


def check_payload(kind: str, payload, controllers) -> dict:
    """``payload`` of an event of ``kind`` checked for its shape (not for the tuning's state: see
    :class:`TuningScratch`); ``controllers``: the names a reset may name. Raises ``ValueError``."""
    if kind not in KINDS:
        raise ValueError(f"unknown event kind {str(kind)[:40]!r} (kinds: {', '.join(KINDS)})")
    if not isinstance(payload, dict):
        raise ValueError(f"{kind} event: payload must be a JSON object")
    unknown = [k for k in payload if k not in KEYS[kind]]
    if unknown:
        raise ValueError(f"{kind} event: unknown key {str(unknown[0])[:40]!r} (keys: {', '.join(KEYS[kind])})")
    if kind == "tuning":
        if not isinstance(payload.get("field"), str) or "new" not in payload:
            raise ValueError("tuning event: needs 'field' (a name) and 'new'")
        if payload.get("channel") is not None and not isinstance(payload["channel"], str):
            raise ValueError("tuning event: 'channel' must be a name or null")
    elif kind in ("reset", "teleport"):
        if kind == "teleport" and "position" not in payload:
            raise ValueError("teleport event: needs 'position'")
        if "position" in payload:
            _numbers(payload["position"], 3, f"{kind} event: position", MAX_POSITION_M)
        if "rotation" in payload:
            q = _numbers(payload["rotation"], 4, "reset event: rotation", 1e6)
            if math.sqrt(sum(v * v for v in q)) < 1e-6:
                raise ValueError("reset event: rotation is not a rotation (length 0)")
        if "yaw_deg" in payload:
            _numbers([payload["yaw_deg"]], 1, "teleport event: yaw_deg", 1e6)
        if "frame" in payload and (not isinstance(payload["frame"], int) or isinstance(payload["frame"], bool)
                                   or payload["frame"] < 0):
            raise ValueError(f"{kind} event: frame must be a database frame (an integer >= 0)")
        names = payload.get("controllers")
        if names is not None:
            if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
                raise ValueError(f"{kind} event: controllers must be a list of names")
            missing = [n for n in names if n not in controllers]
            if missing:
                raise ValueError(f"{kind} event: no controller {missing[0][:40]!r} in this run "
                                 f"(controllers: {', '.join(controllers)})")
    elif kind == "command":
        if not isinstance(payload.get("id"), str) or not isinstance(payload.get("args", {}), dict):
            raise ValueError("command event: needs 'id' (a command id) and optional 'args' (an object)")
    return payload


class TuningScratch:
    """A copy of the start tuning that each tuning event is applied to in order, so that an event naming an
    unknown field, channel or tag, a value out of range, or an ``old`` the tuning did not hold is caught
    before a replay (the ranges are :class:`lmm.tuning.Tuning`'s own)."""

    def __init__(self, start: Tuning):
        self.tuning = start.copy()

    def apply(self, payload: dict) -> None:
        field, channel = payload["field"], payload.get("channel")
        try:
            current = getattr(self.tuning, Tuning.field_info(field).name)
            if channel is not None:
                if not isinstance(current, dict):
                    raise TuningError(f"tuning field {field!r} has no channels (got channel {channel[:40]!r})")
                current = current.get(channel)
            if "old" in payload and (current != payload["old"] or isinstance(current, bool) != isinstance(
                    payload["old"], bool)):
                raise TuningError(f"tuning field {_name(field, channel)!r}: the event's old value "
                                  f"{_short(payload['old'])} is not the {_short(current)} the tuning holds")
            self.tuning.set(field, payload["new"], channel)
        except TuningError as e:
            raise ValueError(str(e)) from None


def _name(field, channel):
    return field if channel is None else f"{field}.{channel}"


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:40] + "..."


def yaw_rotation(yaw_deg: float) -> np.ndarray:
    """The quaternion (w, x, y, z) of ``yaw_deg`` degrees about +Y."""
    half = math.radians(yaw_deg) / 2.0
    return np.array([math.cos(half), 0.0, math.sin(half), 0.0])


def apply_event(event: Event, tuning: Tuning, controllers: dict) -> None:
    """Make ``event`` act on the run: a tuning change through :meth:`Tuning.set` (so it is announced like a
    slider's), a reset or teleport on the controllers it names; a ``command`` changes nothing."""
    p = event.payload
    if event.kind == "tuning":
        tuning.set(p["field"], p["new"], p.get("channel"))
    elif event.kind in ("reset", "teleport"):
        position = p.get("position")
        rotation = p.get("rotation") if event.kind == "reset" else yaw_rotation(p.get("yaw_deg", 0.0))
        for name in p.get("controllers") or list(controllers):
            controllers[name].reset(position=position, rotation=rotation, frame=p.get("frame"))


def check_events(events, start_tuning: Tuning, controllers, n_frames: int, where: str,
                 last_tick: int = MAX_TICKS) -> list[Event]:
    """``events`` (dicts ``{tick, kind, payload}``, as an events file holds them) checked in order against
    the start tuning: ticks whole numbers in ``[0, last_tick]`` and never decreasing, payloads of their
    kind, tuning values in range, frames inside the database. Raises :class:`SessionError` naming
    ``where`` and the event."""
    if not isinstance(events, list):
        raise SessionError(f"{where}: 'events' must be a list of {{tick, kind, payload}} objects")
    if len(events) > MAX_EVENTS:
        raise SessionError(f"{where}: {len(events)} events, more than {MAX_EVENTS} (MAX_EVENTS)")
    scratch = TuningScratch(start_tuning)
    out, previous = [], 0
    for i, e in enumerate(events):
        try:
            if not isinstance(e, dict) or set(e) - {"tick", "kind", "payload"} or "tick" not in e or "kind" not in e:
                raise ValueError("expected an object with 'tick', 'kind' and 'payload'")
            out.append(check_event(e["tick"], e["kind"], e.get("payload", {}), previous, last_tick, scratch,
                                   controllers, n_frames))
            previous = out[-1].tick
        except ValueError as err:
            raise SessionError(f"{where}: event {i}: {err}") from None
    return out


def check_event(tick, kind, payload, previous: int, last_tick: int, scratch: TuningScratch, controllers,
                n_frames: int) -> Event:
    """One event checked (see :func:`check_events`); raises ``ValueError``."""
    if not isinstance(tick, int) or isinstance(tick, bool):
        raise ValueError(f"tick {_short(tick)} is not a whole number")
    if not 0 <= tick <= last_tick:
        raise ValueError(f"tick {tick} is outside [0, {last_tick}]")
    if tick < previous:
        raise ValueError(f"tick {tick} comes after tick {previous} (events must be in tick order)")
    payload = check_payload(kind, payload, controllers)
    if len(json.dumps(payload)) > MAX_PAYLOAD_CHARS:
        raise ValueError(f"payload longer than {MAX_PAYLOAD_CHARS} characters")
    if kind == "tuning":
        scratch.apply(payload)
    if "frame" in payload and payload["frame"] >= n_frames:
        raise ValueError(f"frame {payload['frame']} is outside the database's {n_frames} frames")
    return Event(tick, kind, payload)


def read_events_file(path) -> list:
    """The event list of an ``--events`` file: ``{"events": [{"tick", "kind", "payload"}, ...]}`` (JSON, read
    safely); checked later by :func:`check_events`, once the tuning's channels are known."""
    from lmm.data.jsonio import JsonError, read_json

    try:
        d = read_json(path, "events file", max_bytes=MAX_EVENTS_FILE_BYTES)
    except JsonError as e:
        raise SessionError(str(e)) from None
    if not isinstance(d, dict) or "events" not in d:
        raise SessionError(f"{path}: an events file is a JSON object with an 'events' list")
    unknown = [k for k in d if k not in ("events", "format")]
    if unknown:
        raise SessionError(f"{path}: unknown key {str(unknown[0])[:40]!r} (keys: events, format)")
    return d["events"]
