"""JSON in and out. Out: one converter from what the engine produces (numpy scalars and arrays, paths,
NaN/inf) to strict JSON values, and one atomic writer; every command and the studio's test dump use them.
In: :func:`read_json` / :func:`parse_json`, which read a user's file without ever raising anything but
:class:`JsonError` (one line naming the file): the size is checked before reading, the nesting depth by a
scan that cannot recurse before ``json.loads`` (which recurses per level), and numbers Python refuses
(integers of more than 4300 digits) are reported like any syntax error."""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from lmm.data.atomic import write_text_atomic
from lmm.data.reading import NotRegularFileError, open_regular
from lmm.errors import InputError

#: Deepest nesting of arrays/objects accepted. Our files nest at most 5 levels (a manifest's clip ranges
#: in clips in the manifest, a weights file's feature layout); 64 leaves room and stays far below the
#: interpreter's recursion limit (1000), which json.loads would otherwise hit as a RecursionError.
MAX_JSON_DEPTH = 64
#: Default largest JSON file read (bytes): our presets are ~2 KB, manifests a few KB per hundred clips.
MAX_JSON_BYTES = 4 * 1024 * 1024

_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)


class JsonError(InputError):
    """A JSON file that cannot be read: not found, too big, not UTF-8, too deep or not valid JSON."""


def nesting_depth(text: str) -> int:
    """Deepest ``[``/``{`` nesting of JSON ``text`` (brackets inside strings do not count); linear, no recursion."""
    bare = _STRING.sub('""', text).encode("utf-8", "replace")
    b = np.frombuffer(bare, dtype=np.uint8)
    if b.size == 0:
        return 0
    step = np.isin(b, (ord("["), ord("{"))).astype(np.int64) - np.isin(b, (ord("]"), ord("}")))
    return int(max(np.cumsum(step).max(), 0))


def parse_json(text: str, where, max_depth: int = MAX_JSON_DEPTH):
    """``json.loads(text)``, or :class:`JsonError` starting with ``where`` (the file) and the line/column."""
    depth = nesting_depth(text)
    if depth > max_depth:
        raise JsonError(f"{where}: nested {depth} levels deep, more than {max_depth} (MAX_JSON_DEPTH)")
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise JsonError(f"{where}: not valid JSON (line {e.lineno}, column {e.colno}): {e.msg}") from None
    except RecursionError:
        raise JsonError(f"{where}: nested too deeply (MAX_JSON_DEPTH {max_depth})") from None
    except ValueError as e:  # e.g. an integer of more than sys.get_int_max_str_digits() digits
        raise JsonError(f"{where}: not a usable JSON value: {str(e).split(';')[0]}") from None


def read_json(path, what: str = "JSON file", max_bytes: int = MAX_JSON_BYTES, max_depth: int = MAX_JSON_DEPTH):
    """The JSON value in the file ``path`` (``what`` names it in errors, e.g. "tuning preset")."""
    path = Path(path)
    try:
        with open_regular(path, what) as f:   # a FIFO or a device is refused, never waited on
            data = f.read(max_bytes + 1)  # never more than the limit in memory
    except NotRegularFileError as e:
        raise JsonError(str(e)) from None
    except FileNotFoundError:
        raise JsonError(f"{path}: no such {what}") from None
    except IsADirectoryError:
        raise JsonError(f"{path}: is a folder, expected a {what}") from None
    except OSError as e:
        raise JsonError(f"{path}: cannot read the {what} ({e.strerror})") from None
    if len(data) > max_bytes:
        raise JsonError(f"{path}: {what} larger than {max_bytes} bytes")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise JsonError(f"{path}: {what} is not UTF-8 text (byte {e.start})") from None
    return parse_json(text, path, max_depth)


def json_safe(value):
    """A copy of ``value`` that ``json.dumps`` writes as strict JSON: numpy scalars and arrays become
    numbers and lists, paths strings, NaN and infinities ``null`` (strict JSON has no spelling for them)."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer, int)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        f = float(value)
        return f if math.isfinite(f) else None
    if isinstance(value, Path):
        return str(value)
    if value is None or isinstance(value, str):
        return value
    return str(value)


def write_json(path, value, indent: int | None = 2) -> Path:
    """Write ``json_safe(value)`` to ``path`` atomically (a temporary file in the same folder, then a
    rename), creating the folder. A reader never sees a half-written file; ``OSError`` on failure."""
    return write_text_atomic(path, json.dumps(json_safe(value), indent=indent) + "\n")
