"""Reading a session file: everything checked before anything runs, in bounded time and memory.

:func:`open_session` refuses, with one line naming the file and what is wrong (a :class:`SessionError`):
a file that is not SQLite or not a session, is truncated or malformed, larger than
:data:`~lmm.session.schema.MAX_SESSION_BYTES` (checked before reading), of another schema or a newer format
version, with meta values of the wrong type, tick numbers out of order or beyond the session, input values
out of range, events of unknown kinds or naming unknown tuning fields, channels or tags, or values out of
the ranges :class:`lmm.tuning.Tuning` declares. Rows are read in order through cursors, never all at once.
:func:`check_identity` then compares the database and networks with the ones at hand.
"""
from __future__ import annotations

import json
import math
import os
import re
import sqlite3
from dataclasses import dataclass, field
from pathlib import Path

from lmm.data.inputs import InputState
from lmm.session.actions import Event, TuningScratch, check_event
from lmm.session.schema import (APPLICATION_ID, FORMAT, INPUT_COLUMNS, MAX_AZIMUTH_RAD, MAX_EVENTS,
                                MAX_META_CHARS, MAX_SESSION_BYTES, MAX_TICKS, SCHEMA_VERSION, TABLES,
                                SessionError, ticks_per_second)
from lmm.tuning import Tuning, TuningError

_HEX = re.compile(r"^[0-9a-f]{1,128}$")
MAX_CONTROLLERS = 8
MIN_FPS, MAX_FPS = 1.0, 1000.0


@dataclass
class SessionFile:
    """A checked session (see :mod:`lmm.session.schema` for what each part means)."""
    path: Path
    meta: dict
    controllers: dict[str, tuple[str, str, str]]      # name -> (kind, weights path, weights sha256)
    events: list[Event]
    fingerprints: dict[tuple[int, str], str]           # (tick, controller) -> pose fingerprint
    input_rows: int = 0
    warnings: list[str] = field(default_factory=list)
    _con: sqlite3.Connection | None = field(default=None, repr=False)

    @property
    def fps(self) -> float:
        return float(self.meta["fps"])

    @property
    def dt(self) -> float:
        return 1.0 / self.fps

    @property
    def ticks(self) -> int:
        return int(self.meta["ticks"])

    @property
    def recording_from(self) -> int:
        """The tick the session's recording starts at (meta ``recording``; 0 when it has none)."""
        return int(self.meta.get("recording", {}).get("from_tick", 0))

    @property
    def database(self) -> dict:
        return self.meta["database"]

    def start_tuning(self, channels=None) -> Tuning:
        return Tuning.from_dict(self.meta["tuning"], channels=channels)

    def inputs(self):
        """``(tick, InputState)`` of each input change, in tick order (read as iterated)."""
        cur = self._con.execute(f"SELECT tick, {', '.join(INPUT_COLUMNS)} FROM inputs WHERE tick < ? ORDER BY tick",
                                (self.ticks,))
        for tick, lx, ly, rx, ry, walk, strafe, azimuth in cur:
            yield tick, InputState(lx, ly, rx, ry, bool(walk), bool(strafe), azimuth)

    def close(self) -> None:
        if self._con is not None:
            self._con.close()
            self._con = None


def _fail(path, message: str):
    raise SessionError(f"{path}: {message}")


def _connect(path: Path) -> sqlite3.Connection:
    """Read-only, unless a hot journal (a writer killed mid-transaction) must first be rolled back."""
    if Path(f"{path}-journal").exists():
        return sqlite3.connect(path, isolation_level=None)
    return sqlite3.connect(f"{Path(path).resolve().as_uri()}?mode=ro", uri=True, isolation_level=None)


def open_session(path) -> SessionFile:
    """The session at ``path``, checked whole (see the module doc); raises :class:`SessionError`."""
    path = Path(path)
    try:
        size = os.stat(path).st_size
        if not path.is_file():
            _fail(path, "not a file")
        if size > MAX_SESSION_BYTES:
            _fail(path, f"{size / 2**20:.0f} MiB, more than the {MAX_SESSION_BYTES // 2**20} MiB a session may hold "
                        f"(MAX_SESSION_BYTES)")
        with open(path, "rb") as f:
            head = f.read(100)
    except OSError as e:
        raise SessionError(f"{path}: cannot read: {e.strerror or type(e).__name__}") from None
    if not head.startswith(b"SQLite format 3\0"):
        _fail(path, "not a session file (not an SQLite database)" if head else "empty file, not a session")
    if len(head) < 100:
        _fail(path, "truncated: shorter than an SQLite header")
    con = None
    try:
        con = _connect(path)
        con.execute("PRAGMA query_only=ON")
        session = _read(path, con)
    except sqlite3.DatabaseError as e:
        if con is not None:
            con.close()
        raise SessionError(f"{path}: not a readable session: {str(e)[:120]} (truncated or damaged?)") from None
    except BaseException:
        if con is not None:
            con.close()
        raise
    return session


def _read(path: Path, con: sqlite3.Connection) -> SessionFile:
    app_id = con.execute("PRAGMA application_id").fetchone()[0]
    if app_id != APPLICATION_ID:
        _fail(path, f"an SQLite file but not a session (application_id {app_id:#x}, a session has {APPLICATION_ID:#x})")
    version = con.execute("PRAGMA user_version").fetchone()[0]
    if version != SCHEMA_VERSION:
        _fail(path, f"session format version {version}, this program reads version {SCHEMA_VERSION}"
                    + (" (written by a newer lmm-studio)" if version > SCHEMA_VERSION else ""))
    for table, columns in TABLES.items():
        got = [(r[1], r[2].upper(), r[3], r[5]) for r in con.execute(f"PRAGMA table_info({table})")]
        if got != columns:
            what = "missing" if not got else f"columns {', '.join(c[0] + ' ' + c[1] for c in got)[:120]}"
            _fail(path, f"table {table}: {what}; expected {', '.join(c[0] + ' ' + c[1] for c in columns)}")
    meta = _read_meta(path, con)
    controllers = _read_controllers(path, con)
    session = SessionFile(path, meta, controllers, [], {}, _con=con)
    try:
        start = session.start_tuning()
    except TuningError as e:
        _fail(path, f"meta 'tuning': {e}")
    ticks = session.ticks
    session.input_rows = _check_inputs(path, con, ticks)
    session.events = _read_events(path, con, ticks, start, controllers, int(meta["database"]["frames"]))
    session.fingerprints = _read_fingerprints(path, con, ticks, controllers, ticks_per_second(session.dt))
    return session


def _read_meta(path, con) -> dict:
    from lmm.data.jsonio import JsonError, parse_json

    meta = {}
    for key, value, n in con.execute("SELECT key, substr(value, 1, ?), length(value) FROM meta LIMIT 101",
                                     (MAX_META_CHARS + 1,)):
        if not isinstance(key, str) or not isinstance(value, str):
            _fail(path, f"meta {str(key)[:40]!r}: not text")
        if n > MAX_META_CHARS:
            _fail(path, f"meta {key[:40]!r}: {n} characters, more than {MAX_META_CHARS}")
        try:
            meta[key] = parse_json(value, f"meta {key[:40]!r}")
        except JsonError as e:
            _fail(path, str(e))
    if meta.get("format") != FORMAT:
        _fail(path, f"meta 'format' is {str(meta.get('format'))[:40]!r}, not {FORMAT!r}")
    fps, ticks = meta.get("fps"), meta.get("ticks")
    if not (isinstance(fps, (int, float)) and not isinstance(fps, bool) and math.isfinite(fps)
            and MIN_FPS <= fps <= MAX_FPS):
        _fail(path, f"meta 'fps': expected a number in [{MIN_FPS:g}, {MAX_FPS:g}], got {str(fps)[:40]}")
    if not (isinstance(ticks, int) and not isinstance(ticks, bool) and 0 <= ticks <= MAX_TICKS):
        _fail(path, f"meta 'ticks': expected a whole number in [0, {MAX_TICKS}], got {str(ticks)[:40]}")
    db = meta.get("database")
    if not (isinstance(db, dict) and isinstance(db.get("key"), str) and _HEX.match(db["key"])
            and isinstance(db.get("name"), str) and isinstance(db.get("manifest"), str)
            and isinstance(db.get("frames"), int) and db["frames"] > 0):
        _fail(path, "meta 'database': expected {key (hex), name, manifest, frames}")
    start = meta.get("start")
    if not (isinstance(start, dict) and isinstance(start.get("reset", {}), dict)):
        _fail(path, "meta 'start': expected {input, seconds, reset}")
    from lmm.session.actions import check_payload
    try:
        check_payload("reset", start.get("reset", {}), [])
    except ValueError as e:
        _fail(path, f"meta 'start': {e}")
    recording = meta.get("recording", {"from_tick": 0})
    if not (isinstance(recording, dict) and set(recording) == {"from_tick"}
            and isinstance(recording["from_tick"], int) and not isinstance(recording["from_tick"], bool)
            and 0 <= recording["from_tick"] <= MAX_TICKS):     # after ticks: cut short before the recording
        _fail(path, f"meta 'recording': expected {{from_tick}}, a tick in [0, {MAX_TICKS}]")
    for key, kind in (("tuning", dict), ("program_version", str), ("closed", bool), ("schema_version", int)):
        if not isinstance(meta.get(key), kind):
            _fail(path, f"meta {key!r}: expected {kind.__name__}, got {type(meta.get(key)).__name__}")
    return meta


def _read_controllers(path, con) -> dict:
    rows = con.execute("SELECT name, kind, weights, weights_sha256 FROM controllers LIMIT ?",
                       (MAX_CONTROLLERS + 1,)).fetchall()
    if not rows:
        _fail(path, "no controllers")
    if len(rows) > MAX_CONTROLLERS:
        _fail(path, f"more than {MAX_CONTROLLERS} controllers")
    out = {}
    for name, kind, weights, sha in rows:
        if not (isinstance(name, str) and 0 < len(name) <= 40):
            _fail(path, "controllers: a name must be 1 to 40 characters")
        if kind not in ("mm", "lmm"):
            _fail(path, f"controller {name!r}: unknown kind {str(kind)[:20]!r} (mm or lmm)")
        if not (isinstance(weights, str) and len(weights) < 4096 and isinstance(sha, str)
                and (sha == "" or _HEX.match(sha))):
            _fail(path, f"controller {name!r}: weights must be a path and a sha256 (hex)")
        out[name] = (kind, weights, sha)
    return out


def _check_inputs(path, con, ticks: int) -> int:
    n = 0
    for row in con.execute(f"SELECT tick, {', '.join(INPUT_COLUMNS)} FROM inputs ORDER BY tick"):
        tick = row[0]
        if not isinstance(tick, int) or not 0 <= tick < ticks:
            _fail(path, f"inputs: tick {str(tick)[:30]} is outside the session's {ticks} ticks")
        if n == 0 and tick != 0:
            _fail(path, f"inputs: the first row is at tick {tick}, not 0")
        for name, v in zip(INPUT_COLUMNS, row[1:]):
            if name in ("walk", "strafe"):
                ok = v in (0, 1) and not isinstance(v, float)
            else:
                limit = MAX_AZIMUTH_RAD if name == "camera_azimuth" else 1.0
                ok = isinstance(v, (int, float)) and math.isfinite(v) and abs(v) <= limit
            if not ok:
                _fail(path, f"inputs: tick {tick}: {name} {str(v)[:30]} is out of range")
        n += 1
    if ticks > 0 and n == 0:
        _fail(path, f"inputs: none for the session's {ticks} ticks")
    return n


def _read_events(path, con, ticks: int, start: Tuning, controllers, n_frames: int) -> list[Event]:
    from lmm.data.jsonio import JsonError, parse_json

    scratch = TuningScratch(start)
    events, previous = [], 0
    cur = con.execute("SELECT seq, tick, kind, substr(payload, 1, 65537), length(payload) FROM events ORDER BY seq "
                      "LIMIT ?", (MAX_EVENTS + 1,))
    for seq, tick, kind, payload, n in cur:
        if len(events) >= MAX_EVENTS:
            _fail(path, f"more than {MAX_EVENTS} events (MAX_EVENTS)")
        where = f"event {seq} (tick {str(tick)[:30]})"
        if not isinstance(payload, str) or n > 65536:
            _fail(path, f"{where}: payload is not JSON text of at most 65536 characters")
        try:
            value = parse_json(payload, where)
        except JsonError as e:
            _fail(path, str(e))
        try:
            event = check_event(tick, kind, value, previous, ticks, scratch, controllers, n_frames)
        except ValueError as e:
            _fail(path, f"{where}: {e}")
        events.append(event)
        previous = event.tick
    return events


def _read_fingerprints(path, con, ticks: int, controllers, every: int) -> dict:
    most = (ticks // every + 1) * len(controllers)
    out = {}
    for tick, name, pose in con.execute("SELECT tick, controller, pose FROM fingerprints ORDER BY tick LIMIT ?",
                                        (most + 1,)):
        if len(out) >= most:
            _fail(path, f"fingerprints: more than one a second ({most}) for {ticks} ticks")
        if not isinstance(tick, int) or not 0 <= tick < ticks:
            _fail(path, f"fingerprints: tick {str(tick)[:30]} is outside the session's {ticks} ticks")
        if name not in controllers:
            _fail(path, f"fingerprints: tick {tick}: no controller {str(name)[:40]!r}")
        if not (isinstance(pose, str) and len(pose) == 32 and _HEX.match(pose)):
            _fail(path, f"fingerprints: tick {tick}: not a 32-digit hex fingerprint")
        out[(tick, name)] = pose
    return out


def check_identity(session: SessionFile, db, weights: dict | None = None) -> list[str]:
    """Refuse a session recorded on another database (content hash) or other networks (file sha256);
    ``weights``: controller name -> the networks file that will run it (default: the recorded path).
    Returns the warnings a replay can go on with (another program version)."""
    from lmm import __version__
    from lmm.data.derived import file_digest

    path, rec = session.path, session.database
    if db.key != rec["key"]:
        _fail(path, f"recorded on database {rec['name']!r} (key {rec['key'][:12]}, manifest "
                    f"{rec['manifest'] or 'shipped'}), this database {db.name!r} has key {db.key[:12]}: "
                    f"pass --manifest with the recorded one")
    for name, (kind, recorded, sha) in session.controllers.items():
        if kind != "lmm":
            continue
        use = (weights or {}).get(name) or recorded
        try:
            digest = file_digest(use)
        except OSError as e:
            _fail(path, f"controller {name!r}: its networks {use} cannot be read: {e.strerror or type(e).__name__}")
        if digest != sha:
            _fail(path, f"controller {name!r}: recorded with networks sha256 {sha[:12]}, {use} has {digest[:12]}")
    warnings = []
    if session.meta["program_version"] != __version__:
        warnings.append(f"{path}: recorded by lmm-studio {session.meta['program_version'][:40]}, this is "
                        f"{__version__}; replaying anyway (the fingerprints tell whether it matches)")
    return warnings
