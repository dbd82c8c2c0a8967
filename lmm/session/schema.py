"""The session file's format: one SQLite file (stdlib ``sqlite3``), its tables, limits and pose fingerprint.

A session keeps what reproduces a run exactly and nothing that can be recomputed: the identities of the
database and networks, the tick rate, the start state and tuning, the input of every tick (as changes),
every tuning change and action stamped with its tick, and a fingerprint of each controller's pose every
second so that a replay proves it matches. Any program can write one (README, "Sessions")::

    meta(key TEXT PRIMARY KEY, value TEXT NOT NULL)         -- one JSON value per key (see META_KEYS)
    controllers(name TEXT PRIMARY KEY, kind TEXT NOT NULL,   -- "mm" | "lmm"
                weights TEXT NOT NULL, weights_sha256 TEXT NOT NULL)   -- "" for mm
    inputs(tick INTEGER PRIMARY KEY, left_x REAL NOT NULL, left_y REAL NOT NULL, right_x REAL NOT NULL,
           right_y REAL NOT NULL, walk INTEGER NOT NULL, strafe INTEGER NOT NULL,
           camera_azimuth REAL NOT NULL)                    -- the input from this tick on (changes only)
    events(seq INTEGER PRIMARY KEY, tick INTEGER NOT NULL, kind TEXT NOT NULL, payload TEXT NOT NULL)
    fingerprints(tick INTEGER NOT NULL, controller TEXT NOT NULL, pose TEXT NOT NULL,
                 PRIMARY KEY (tick, controller)) WITHOUT ROWID

Ticks count from 0 at ``fps`` ticks per second (``dt = 1.0 / fps``); tick ``i`` is the step from ``i * dt`` to ``(i + 1) * dt`` seconds. An event at tick
``i`` acts before tick ``i`` is stepped; a fingerprint at tick ``i`` is of the pose tick ``i`` produced.
``meta.ticks`` is the number of ticks stored whole: it is written in the same transaction as their rows,
so a file cut short by a crash reopens at its last committed tick. Input and fingerprint rows at or after
``ticks``, and events after it, are an error (a writer never leaves them).
"""
from __future__ import annotations

import hashlib

import numpy as np

from lmm.errors import InputError

FORMAT = "lmm-studio session"
SCHEMA_VERSION = 1
#: ``PRAGMA application_id`` of a session file ("LMMS"), so a foreign SQLite file is told apart at once
APPLICATION_ID = 0x4C4D4D53
SUFFIX = ".lmmsession"

#: Largest session file read (bytes). Ten minutes at 60 Hz is well under 1 MB (README, "Sessions"); a day of
#: input changing every tick is about 200 MB.
MAX_SESSION_BYTES = 512 * 1024 * 1024
#: Most ticks a session may hold: a day at the highest tick rate ``run`` accepts (1000 Hz).
MAX_TICKS = 86_400_000
#: Most events (tuning changes and actions) and the largest event payload / meta value (characters).
MAX_EVENTS = 200_000
MAX_PAYLOAD_CHARS = 64 * 1024
MAX_META_CHARS = 1024 * 1024
#: The largest distance a reset or teleport may move a character (metres) and the largest camera azimuth
#: magnitude of an input row (radians; the input logs' limit).
MAX_POSITION_M = 1.0e5
MAX_AZIMUTH_RAD = 1.0e6

#: Ticks between transactions and fingerprints: one second of the session (at least one tick).
def ticks_per_second(dt: float) -> int:
    return max(1, int(round(1.0 / dt)))


META_KEYS = {
    "format": "the string 'lmm-studio session'",
    "schema_version": "integer, this format's version (1)",
    "program_version": "the lmm-studio version that wrote it",
    "created_utc": "ISO 8601 time the session started",
    "fps": "ticks per second; a tick is dt = 1.0 / fps seconds",
    "database": "{key, name, manifest, frames}: key is the database's content hash (lmm.data.cache.manifest_key); "
                "manifest the path it was built from ('' : the shipped one)",
    "start": "{input, seconds, reset}: the input it was driven by (a log path or builtin:NAME, a name only), "
             "the length asked for, and the keyword arguments of the controllers' first reset",
    "tuning": "the full tuning at tick 0 (lmm.tuning.Tuning.to_dict, the database's channels and tags named)",
    "ticks": "integer, ticks stored whole (rows of later ticks are ignored)",
    "closed": "true once the writer closed the file (false: the run was cut short)",
    "recording": "optional {from_tick}: the session was kept for a recording that starts at that tick (the "
                 "studio's: its session starts at the characters' last reset); a replay records from there",
}

TABLES = {  # name -> [(column, declared type, not null, primary key position)] as PRAGMA table_info shows
    "meta": [("key", "TEXT", 0, 1), ("value", "TEXT", 1, 0)],
    "controllers": [("name", "TEXT", 0, 1), ("kind", "TEXT", 1, 0), ("weights", "TEXT", 1, 0),
                    ("weights_sha256", "TEXT", 1, 0)],
    "inputs": [("tick", "INTEGER", 0, 1), ("left_x", "REAL", 1, 0), ("left_y", "REAL", 1, 0),
               ("right_x", "REAL", 1, 0), ("right_y", "REAL", 1, 0), ("walk", "INTEGER", 1, 0),
               ("strafe", "INTEGER", 1, 0), ("camera_azimuth", "REAL", 1, 0)],
    "events": [("seq", "INTEGER", 0, 1), ("tick", "INTEGER", 1, 0), ("kind", "TEXT", 1, 0),
               ("payload", "TEXT", 1, 0)],
    "fingerprints": [("tick", "INTEGER", 1, 1), ("controller", "TEXT", 1, 2), ("pose", "TEXT", 1, 0)],
}
INPUT_COLUMNS = [c[0] for c in TABLES["inputs"][1:]]

DDL = """
CREATE TABLE meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE controllers(name TEXT PRIMARY KEY, kind TEXT NOT NULL, weights TEXT NOT NULL,
                         weights_sha256 TEXT NOT NULL);
CREATE TABLE inputs(tick INTEGER PRIMARY KEY, left_x REAL NOT NULL, left_y REAL NOT NULL, right_x REAL NOT NULL,
                    right_y REAL NOT NULL, walk INTEGER NOT NULL, strafe INTEGER NOT NULL,
                    camera_azimuth REAL NOT NULL);
CREATE TABLE events(seq INTEGER PRIMARY KEY, tick INTEGER NOT NULL, kind TEXT NOT NULL, payload TEXT NOT NULL);
CREATE TABLE fingerprints(tick INTEGER NOT NULL, controller TEXT NOT NULL, pose TEXT NOT NULL,
                          PRIMARY KEY (tick, controller)) WITHOUT ROWID;
"""


class SessionError(InputError):
    """A session file that cannot be read or replayed; ``str(e)`` names the file and what is wrong."""


def pose_fingerprint(pose) -> str:
    """BLAKE2b-128 (hex) of the pose: local positions, local rotations, global positions and global
    rotations as little-endian float64 (exact for the float32 poses), then the two contacts as bytes.
    Equal fingerprints mean equal poses bit for bit (up to a 2^-128 chance)."""
    h = hashlib.blake2b(digest_size=16)
    for a in (pose.local_positions, pose.local_rotations, pose.global_positions, pose.global_rotations):
        h.update(np.ascontiguousarray(a, dtype="<f8").tobytes())
    h.update(np.ascontiguousarray(pose.contacts, dtype=np.uint8).tobytes())
    return h.hexdigest()
