"""Opening a user's file for reading: only a regular file is read, with its size known before the first
byte. A FIFO would block ``open`` forever, ``/dev/zero`` or ``/dev/urandom`` report 0 bytes and never end,
a folder or a loop of links cannot be read at all; each is refused here in one line naming the file, so
every reader (input logs, presets, manifests and their feature files, BVH takes) has the same guarantee.
"""
from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from lmm.errors import InputError


class NotRegularFileError(InputError):
    """A path that is not a regular file (a FIFO, a device, a socket, a folder)."""


def kind_of(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, in words (for the one-line error)."""
    for test, name in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISLNK, "a symbolic link")):
        if test(mode):
            return name
    return "not a regular file"


def not_regular(path, what: str) -> str:
    """Why ``path``, which is not a regular file, cannot be read as a ``what`` (for the one-line error):
    ``WHAT not found`` when nothing is there, else what is there (a FIFO, a device, a folder: those said
    "not found" too) or why it cannot be looked at."""
    try:
        return f"is {kind_of(os.stat(path).st_mode)}, expected a regular {what}"
    except FileNotFoundError:
        return f"{what} not found"
    except OSError as e:
        return f"cannot be opened: {e.strerror or type(e).__name__}"


def open_regular(path, what: str = "file"):
    """``open(path, "rb")`` for a regular file only. The file is opened with ``O_NONBLOCK`` so a FIFO
    cannot block the open itself, then checked with ``fstat`` on the very descriptor that is read (no
    window between a check and the open). Raises :class:`NotRegularFileError` naming the file and what
    it is; ``OSError`` (missing file, no permission, a loop of links) passes through naming the path."""
    p = os.fspath(path)
    fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise NotRegularFileError(f"{p}: is {kind_of(st.st_mode)}, expected a regular {what}")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_limited(path, max_bytes: int, what: str = "file") -> bytes:
    """The bytes of the regular file ``path``; ``InputError`` naming the file if it holds more than
    ``max_bytes`` (checked on its size before reading, and again on what was read, never more than
    ``max_bytes + 1`` bytes in memory)."""
    with open_regular(path, what) as f:
        if os.fstat(f.fileno()).st_size > max_bytes:
            raise InputError(f"{os.fspath(path)}: {what} larger than {max_bytes} bytes")
        data = f.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise InputError(f"{os.fspath(path)}: {what} larger than {max_bytes} bytes")
    return data


def resolved(path) -> Path:
    """``path`` with links and ``..`` resolved (missing tails kept); a loop of links is an ``OSError``
    (``ELOOP``) naming the path, not Python 3.11's ``RuntimeError``."""
    try:
        return Path(os.fspath(path)).resolve()
    except RuntimeError:
        raise OSError(errno.ELOOP, "a loop of symbolic links", os.fspath(path)) from None


def ascii_float(text: str) -> float:
    """``float(text)`` for numbers as text formats write them: ASCII only. Python's ``float`` also takes
    ``9_7.0`` (digit grouping) and other scripts' digits (``٣``); BVH and CSV do not, so neither do we.
    Raises ``ValueError``."""
    if not text.isascii() or "_" in text:
        raise ValueError(f"not an ASCII number: {text[:20]!r}")
    return float(text)


def ascii_int(text: str) -> int:
    """``int(text)`` for ASCII digits only (see :func:`ascii_float`). Raises ``ValueError``."""
    if not text.isascii() or "_" in text:
        raise ValueError(f"not an ASCII integer: {text[:20]!r}")
    return int(text)
