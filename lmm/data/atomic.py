"""Atomic file output: every file the project writes whole (databases, caches, weights, JSON, BVH,
input logs) goes through :func:`atomic_write`, so a reader never sees a half-written file and a
crash or a full disk never leaves one behind under the real name. Streams (live recordings) are the
exception; see :mod:`lmm.data.recording`."""
from __future__ import annotations

import os
import secrets
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def atomic_write(path, mode: str = "wb", encoding: str | None = None):
    """``with atomic_write(path) as f: ...`` writes to a temporary file beside ``path`` (same folder,
    so the rename cannot cross file systems) and renames it over ``path`` when the block ends without
    an exception; on any exception the temporary file is removed and ``path`` is left as it was.
    The folder is created if needed. ``mode`` is ``"wb"`` or ``"w"`` (text, UTF-8 by default)."""
    if mode not in ("wb", "w"):
        raise ValueError(f"atomic_write mode must be 'wb' or 'w', got {mode!r}")
    path = Path(os.fspath(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        binary = mode == "wb"
        with open(tmp, "xb" if binary else "x", encoding=None if binary else (encoding or "utf-8")) as f:
            yield f
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def write_bytes_atomic(path, data: bytes) -> Path:
    with atomic_write(path, "wb") as f:
        f.write(data)
    return Path(path)


def write_text_atomic(path, text: str) -> Path:
    with atomic_write(path, "w") as f:
        f.write(text)
    return Path(path)
