"""JSON output: one converter from what the engine produces (numpy scalars and arrays, paths, NaN/inf)
to strict JSON values, and one atomic writer. Every command and the studio's test dump use these."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from lmm.data.atomic import write_text_atomic


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
