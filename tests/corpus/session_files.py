"""Hostile session files (issue 33), each made from a valid session with one thing wrong.

``make_good(path)`` records a 2 s session with ``lmm-studio run --session`` (a subprocess, so it works from
the corpus generator); ``make_bad(good, folder)`` writes every case of :data:`BAD` into ``folder``. The same
files serve the corpus (tests/corpus/corpus_cases.py, ``replay`` on each) and tests/lmm/session/test_session.py.
"""
from __future__ import annotations

import json
import os
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: file name -> (what is wrong, a word the error line must hold besides the file's name)
BAD = {
    "empty.lmmsession": ("an empty file", None),
    "not_sqlite.lmmsession": ("a text file named .lmmsession", "SQLite"),
    "truncated.lmmsession": ("the first half of a valid session", None),
    "foreign_sqlite.lmmsession": ("an SQLite file of another program", "not a session"),
    "version_99.lmmsession": ("format version 99 (a newer writer)", "version"),
    "wrong_schema.lmmsession": ("the inputs table without its camera_azimuth column", "inputs"),
    "events_out_of_order.lmmsession": ("an event at tick 3 after the last one (tick 70 or later)", "tick"),
    "input_tick_huge.lmmsession": ("an input row at tick 10^12", "tick"),
    "meta_ticks_huge.lmmsession": ("meta ticks 10^15", "ticks"),
    "unknown_field.lmmsession": ("a tuning change of a field that does not exist", "no_such_field"),
    "unknown_channel.lmmsession": ("a feature weight of a channel that does not exist", "no_such_channel"),
    "value_out_of_range.lmmsession": ("stick_deadzone set to 5 (range 0..0.9)", "stick_deadzone"),
    "unknown_kind.lmmsession": ("an event of kind 'explode'", "explode"),
    "payload_not_json.lmmsession": ("an event payload that is not JSON", "JSON"),
    "input_out_of_range.lmmsession": ("a stick value of 5", "left_x"),
    "other_database.lmmsession": ("recorded on another database (its key changed)", "database"),
    "huge_1gib.lmmsession": ("a valid session padded to 1 GiB (sparse)", "MiB"),
}


def make_good(path: Path, seconds: float = 2.0, env: dict | None = None) -> Path:
    """A valid mm session of ``seconds`` on builtin:circle with a tuning change and a reset."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    events = path.with_suffix(".events.json")
    events.write_text(json.dumps({"events": [
        {"tick": 20, "kind": "tuning", "payload": {"field": "search_interval_s", "new": 0.2}},
        {"tick": 60, "kind": "reset", "payload": {}},
        {"tick": 70, "kind": "tuning", "payload": {"field": "stick_deadzone", "new": 0.25}}]}))
    subprocess.run([sys.executable, "-m", "app.cli", "run", "--input", "builtin:circle", "--seconds", str(seconds),
                    "--events", str(events), "--session", str(path), "--quiet"],
                   cwd=ROOT, env={**os.environ, **(env or {}), "PYTHONPATH": str(ROOT)}, check=True)
    return path


def _edit(good: Path, out: Path, *statements) -> None:
    shutil.copyfile(good, out)
    con = sqlite3.connect(out, isolation_level=None)
    try:
        for s in statements:
            con.execute(*s) if isinstance(s, tuple) else con.execute(s)
    finally:
        con.close()


def _event(kind: str, payload, tick: int | None = None) -> tuple:
    """An event appended to the session (at the last event's tick unless ``tick`` is given)."""
    text = payload if isinstance(payload, str) else json.dumps(payload)
    if tick is None:
        return ("INSERT INTO events (tick, kind, payload) VALUES ((SELECT coalesce(max(tick), 0) FROM events), ?, ?)",
                (kind, text))
    return ("INSERT INTO events (tick, kind, payload) VALUES (?, ?, ?)", (tick, kind, text))


def make_bad(good: Path, folder: Path, only=None) -> dict[str, Path]:
    """Every :data:`BAD` case (or those named in ``only``) made from the valid session ``good``."""
    folder.mkdir(parents=True, exist_ok=True)
    made = {}
    for name in BAD:
        if only is not None and name not in only:
            continue
        out = folder / name
        if name == "empty.lmmsession":
            out.write_bytes(b"")
        elif name == "not_sqlite.lmmsession":
            out.write_text("this is not a session\n")
        elif name == "truncated.lmmsession":
            data = good.read_bytes()
            out.write_bytes(data[:len(data) // 2])
        elif name == "foreign_sqlite.lmmsession":
            con = sqlite3.connect(out)
            con.execute("CREATE TABLE t(x)")
            con.commit()
            con.close()
        elif name == "version_99.lmmsession":
            _edit(good, out, "PRAGMA user_version=99")
        elif name == "wrong_schema.lmmsession":
            _edit(good, out, "ALTER TABLE inputs DROP COLUMN camera_azimuth")
        elif name == "events_out_of_order.lmmsession":
            _edit(good, out, _event("tuning", {"field": "stick_deadzone", "channel": None, "new": 0.3},
                                    tick=3))
        elif name == "input_tick_huge.lmmsession":
            _edit(good, out, "UPDATE inputs SET tick = 1000000000000 WHERE tick = (SELECT max(tick) FROM inputs)")
        elif name == "meta_ticks_huge.lmmsession":
            _edit(good, out, "UPDATE meta SET value = '1000000000000000' WHERE key = 'ticks'")
        elif name == "unknown_field.lmmsession":
            _edit(good, out, _event("tuning", {"field": "no_such_field", "channel": None, "new": 1.0}))
        elif name == "unknown_channel.lmmsession":
            _edit(good, out, _event("tuning", {"field": "feature_weights", "channel": "no_such_channel", "new": 1.0}))
        elif name == "value_out_of_range.lmmsession":
            _edit(good, out, _event("tuning", {"field": "stick_deadzone", "channel": None, "new": 5.0}))
        elif name == "unknown_kind.lmmsession":
            _edit(good, out, _event("explode", {}))
        elif name == "payload_not_json.lmmsession":
            _edit(good, out, _event("reset", "{not json"))
        elif name == "input_out_of_range.lmmsession":
            _edit(good, out, "UPDATE inputs SET left_x = 5.0 WHERE tick = 0")
        elif name == "other_database.lmmsession":
            meta = "json_set(value, '$.key', '" + "ab" * 32 + "')"
            _edit(good, out, f"UPDATE meta SET value = {meta} WHERE key = 'database'")
        elif name == "huge_1gib.lmmsession":
            shutil.copyfile(good, out)
            with open(out, "r+b") as f:
                f.truncate(1 << 30)      # sparse: no disk used
        made[name] = out
    return made
