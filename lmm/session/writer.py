"""Writing a session as it goes (see :mod:`lmm.session.schema`): crash-safe, small.

The file is made whole under a temporary name (tables and meta committed), then renamed into place, so a
kill at any moment leaves either no file or one that opens. Rows are then added in transactions of one
second of ticks: the ``ticks`` meta value moves in the same transaction as the rows, so a file cut short
reopens up to its last committed tick (SQLite's rollback journal undoes a half-written transaction the
next time the file is opened).

The writer listens to ``tuning.events``: every change (a slider, a preset, an ``--events`` entry) is
stored as a ``tuning`` event at the tick it acts on; actions are stored with :meth:`SessionWriter.event`
(the studio's command registry can call it for each command run).
"""
from __future__ import annotations

import datetime
import json
import os
import sqlite3
from pathlib import Path

from lmm.session.schema import (APPLICATION_ID, DDL, FORMAT, INPUT_COLUMNS, SCHEMA_VERSION, pose_fingerprint,
                                ticks_per_second)


def database_identity(db, manifest) -> dict:
    """What a session stores of its database: content hash (``db.key``), name, manifest path, frames."""
    return {"key": db.key, "name": db.name, "manifest": "" if manifest is None else str(Path(manifest).resolve()),
            "frames": db.n_frames}


def controller_identity(name: str, controller) -> tuple[str, str, str, str]:
    """``(name, kind, weights path, weights sha256)`` of a controller ("" for one without networks)."""
    from lmm.data.derived import file_digest

    path = controller.capabilities().networks_path
    if not path:
        return name, controller.name, "", ""
    return name, controller.name, str(Path(path).resolve()), file_digest(path)


class SessionWriter:
    """Stores a session in ``path`` while it runs.

    ``begin_tick(i, input)`` before stepping tick ``i`` (stores the input if it changed), ``end_tick(i,
    poses)`` after (fingerprints every second, commits every second), ``event(kind, payload)`` for an
    action at the tick about to be stepped, ``close()`` at the end."""

    def __init__(self, path, *, fps: float, db, manifest, controllers: dict, tuning, start: dict,
                 program_version: str | None = None, start_tuning: dict | None = None,
                 recording_from: int | None = None):
        """``start_tuning``: the tuning at tick 0 when it is not ``tuning``'s present value (the studio starts
        a session at its last reset, before the changes :meth:`write_past` adds); ``recording_from``: the
        tick a recording of this session starts at (meta ``recording``; a replay records from there)."""
        from lmm import __version__

        self.path = Path(path)
        self.fps = float(fps)
        self.dt = 1.0 / self.fps               # as run computes it: the same ticks
        self.every = ticks_per_second(self.dt)
        self.tick = 0                         # the tick the next event acts on
        self._last_input = None
        self._last_fingerprint_tick = -1
        self._pending = 0
        meta = {"format": FORMAT, "schema_version": SCHEMA_VERSION,
                "program_version": program_version or __version__,
                "created_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
                "fps": self.fps, "database": database_identity(db, manifest), "start": start,
                "tuning": start_tuning if start_tuning is not None else tuning.to_dict(), "ticks": 0,
                "closed": False}
        if recording_from is not None:
            meta["recording"] = {"from_tick": int(recording_from)}
        rows = [controller_identity(name, c) for name, c in controllers.items()]
        self._make(meta, rows)
        # the studio calls it from its GUI thread (tuning changes) and its tick thread (ticks), never at once
        self._db = sqlite3.connect(self.path, isolation_level=None, check_same_thread=False)
        self._db.execute("PRAGMA synchronous=NORMAL")
        self._db.execute("BEGIN")
        self._tuning = tuning
        tuning.events.connect(self._on_tuning_change)

    def _make(self, meta: dict, controllers: list) -> None:
        """The file with its tables, meta and controllers, made under a temporary name and renamed in."""
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        for p in (tmp, Path(f"{tmp}-journal")):
            p.unlink(missing_ok=True)
        con = sqlite3.connect(tmp, isolation_level=None)
        try:
            con.execute(f"PRAGMA application_id={APPLICATION_ID}")
            con.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
            con.execute("BEGIN")
            for statement in DDL.split(";"):   # not executescript: it would commit on its own
                if statement.strip():
                    con.execute(statement)
            con.executemany("INSERT INTO meta VALUES (?, ?)",
                            [(k, json.dumps(v, sort_keys=True, allow_nan=False)) for k, v in meta.items()])
            con.executemany("INSERT INTO controllers VALUES (?, ?, ?, ?)", controllers)
            con.execute("COMMIT")
        finally:
            con.close()
        # a journal left beside an older file of this name (a killed run) would be "rolled back" into this one
        Path(f"{self.path}-journal").unlink(missing_ok=True)
        os.replace(tmp, self.path)

    # -- per tick ------------------------------------------------------------------------------------
    def begin_tick(self, tick: int, inp) -> None:
        """Tick ``tick`` is about to be stepped with ``inp``: stored when it differs from the last input."""
        self.tick = tick
        row = (inp.left_x, inp.left_y, inp.right_x, inp.right_y, int(bool(inp.walk)), int(bool(inp.strafe)),
               inp.camera_azimuth)
        if row != self._last_input:
            self._db.execute(f"INSERT INTO inputs (tick, {', '.join(INPUT_COLUMNS)}) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                             (tick, *(float(v) if i not in (4, 5) else v for i, v in enumerate(row))))
            self._last_input = row

    def end_tick(self, tick: int, poses: dict) -> None:
        """Tick ``tick`` was stepped; ``poses``: each controller's pose. Fingerprints and a commit once a second."""
        self.tick = tick + 1
        self._pending += 1
        if (tick + 1) % self.every == 0:
            self._fingerprint(tick, poses)
            self._commit(tick + 1)

    def event(self, kind: str, payload: dict, tick: int | None = None) -> None:
        """Store an action (``reset``, ``teleport``, ``command``; see :mod:`lmm.session.actions`) acting at
        ``tick`` (default: the tick about to be stepped)."""
        self._db.execute("INSERT INTO events (tick, kind, payload) VALUES (?, ?, ?)",
                         (self.tick if tick is None else int(tick), kind,
                          json.dumps(payload, sort_keys=True, allow_nan=False)))

    def write_past(self, inputs, events, fingerprints, ticks: int) -> None:
        """Ticks ``0 .. ticks - 1`` stepped before this writer was made, committed at once: ``inputs``
        ``(tick, InputState)`` changes, ``events`` ``(tick, kind, payload)``, ``fingerprints`` ``(tick,
        controller, pose fingerprint)``; the next tick stored is ``ticks``."""
        for tick, inp in inputs:
            self.begin_tick(tick, inp)
        for tick, kind, payload in events:
            self.event(kind, payload, tick)
        self._db.executemany("INSERT OR REPLACE INTO fingerprints VALUES (?, ?, ?)", list(fingerprints))
        self.tick = int(ticks)
        self._commit(self.tick)

    def _on_tuning_change(self, change) -> None:
        self.event("tuning", tuning_payload(change))

    def _fingerprint(self, tick: int, poses: dict) -> None:
        self._db.executemany("INSERT OR REPLACE INTO fingerprints VALUES (?, ?, ?)",
                             [(tick, name, pose_fingerprint(pose)) for name, pose in poses.items()])
        self._last_fingerprint_tick = tick

    def _commit(self, ticks: int) -> None:
        self._db.execute("UPDATE meta SET value = ? WHERE key = 'ticks'", (json.dumps(ticks),))
        self._db.execute("COMMIT")
        self._db.execute("BEGIN")
        self._pending = 0

    def close(self, last_poses: dict | None = None) -> None:
        """Fingerprint the last tick (``last_poses``), commit and close; the file is then marked closed."""
        if self._db is None:
            return
        self._tuning.events.disconnect(self._on_tuning_change)
        try:
            last = self.tick - 1
            if last_poses and last >= 0 and last != self._last_fingerprint_tick:
                self._fingerprint(last, last_poses)
            self._db.execute("UPDATE meta SET value = 'true' WHERE key = 'closed'")
            self._commit(self.tick)
            self._db.execute("COMMIT")
        finally:
            self._db.close()
            self._db = None


def tuning_payload(change) -> dict:
    """A :class:`lmm.tuning.TuningChange` as a ``tuning`` event's payload."""
    return {"field": change.field, "channel": change.channel, "old": _plain(change.old), "new": _plain(change.new)}


def _plain(value):
    """A tuning value as JSON holds it (an entries dict as a plain dict)."""
    return dict(value) if isinstance(value, dict) else value
