"""Atomic file output: every file the project writes whole (databases, caches, weights, JSON, BVH,
input logs) goes through :func:`atomic_write`, so a reader never sees a half-written file and a
crash or a full disk never leaves one behind under the real name. Streams (live recordings) are the
exception; see :mod:`lmm.data.recording`."""
from __future__ import annotations

import errno
import os
import secrets
import stat
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def atomic_write(path, mode: str = "wb", encoding: str | None = None):
    """``with atomic_write(path) as f: ...`` writes to a temporary file beside ``path`` (same folder,
    so the rename cannot cross file systems) and renames it over ``path`` when the block ends without
    an exception; on any exception the temporary file is removed and ``path`` is left as it was.
    The folder is created if needed. ``mode`` is ``"wb"`` or ``"w"`` (text, UTF-8 by default).
    An ``OSError`` (read-only folder, full disk) is re-raised naming ``path``, not the temporary file."""
    if mode not in ("wb", "w"):
        raise ValueError(f"atomic_write mode must be 'wb' or 'w', got {mode!r}")
    path = Path(os.fspath(path))
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        binary = mode == "wb"
        with open(tmp, "xb" if binary else "x", encoding=None if binary else (encoding or "utf-8")) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())   # the data is on disk before the name points at it (a crash keeps the old file)
        replace_regular(tmp, path)
    except BaseException as e:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(e, OSError) and e.errno is not None and e.filename in (None, str(tmp), tmp):
            raise type(e)(e.errno, e.strerror, str(path)) from None  # name the file the user asked for
        raise


def replace_regular(tmp, path) -> None:
    """``os.replace(tmp, path)`` unless ``path`` exists and is neither a regular file nor a link: a rename
    would put a file where a device (``/dev/null``), a FIFO or a socket was. ``OSError`` naming ``path``."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        mode = None
    if mode is not None and not (stat.S_ISREG(mode) or stat.S_ISLNK(mode)):
        raise OSError(errno.EEXIST, "exists and is not a regular file; not replaced", os.fspath(path))
    os.replace(tmp, path)


def check_writable(path) -> None:
    """Raise ``OSError`` naming ``path`` unless a file can be created in its folder (made if missing):
    checked before a long computation so a read-only target fails at once, not after the work."""
    path = Path(os.fspath(path))
    probe = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.probe")
    try:
        if path.is_dir():
            raise IsADirectoryError(errno.EISDIR, "is a folder, expected a file name", str(path))
        existing = next(p for p in path.parents if p.exists() or p == p.parent)
        if not existing.is_dir():
            raise NotADirectoryError(errno.ENOTDIR, f"{existing} is a file, not a folder", str(path))
        path.parent.mkdir(parents=True, exist_ok=True)
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        os.unlink(probe)
    except OSError as e:
        raise type(e)(e.errno, e.strerror, str(path)) from None


def write_bytes_atomic(path, data: bytes) -> Path:
    with atomic_write(path, "wb") as f:
        f.write(data)
    return Path(path)


def write_text_atomic(path, text: str) -> Path:
    with atomic_write(path, "w") as f:
        f.write(text)
    return Path(path)
