"""A command's output paths, checked once before any work: nothing a command writes may destroy one of its
own inputs, another of its outputs, or something that is not a file.

Every ``lmm-studio`` command that writes files calls :func:`check_outputs` with its outputs and inputs
before it loads anything. Each output path is resolved (symbolic links, ``..``) and refused in one line
if it is the same file as an input (same resolved path, or the same inode: a hard link) or as another
output, or if it exists and is not a regular file (a device such as ``/dev/null``, a FIFO, a folder).
Then it is probed for writing (:func:`lmm.data.atomic.check_writable`) and locked: a second process
that wants to write the same path while the first still runs is refused at once, naming the holder's
process id. Locks are ``flock`` locks on small files in a per-user folder under the system's temporary
folder (never beside the user's files); the kernel drops them when a process ends however it ends, and
:func:`release_locks` (called by ``app/cli.py`` when a command returns) removes the files.
"""
from __future__ import annotations

import hashlib
import os
import stat
import tempfile
from pathlib import Path

from lmm.data.reading import kind_of, resolved
from lmm.errors import InputError

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: no locks, the other checks still hold
    fcntl = None


class OutputError(InputError):
    """An output path that would destroy an input, another output or a special file, or that is locked."""


def _pairs(items):
    """``(option, path)`` pairs from ``items`` of pairs or bare paths (None entries dropped)."""
    for item in items:
        option, path = item if isinstance(item, tuple) else ("", item)
        if path is not None and os.fspath(path) != "":
            yield option, Path(os.fspath(path))


def _identity(path: Path):
    """``(resolved path, (st_dev, st_ino) or None)`` of ``path``."""
    rp = resolved(path)
    try:
        st = os.stat(rp)
    except OSError:
        return rp, None
    return rp, (st.st_dev, st.st_ino)


def _same(a, b) -> bool:
    return a[0] == b[0] or (a[1] is not None and a[1] == b[1])


def _named(option: str, path: Path) -> str:
    return f"{option} ({path})" if option else str(path)


def check_output_kind(out: Path, option: str = "") -> None:
    """Refuse ``out`` if it exists and is not a regular file (links followed)."""
    try:
        st = os.stat(out)
    except OSError:   # missing, or a folder in its path is a file: check_writable says which
        return
    if not stat.S_ISREG(st.st_mode):
        where = f"{option}: " if option else ""
        raise OutputError(f"{out}: {where}is {kind_of(st.st_mode)}, expected a regular file or a new name")


def check_outputs(outputs, inputs=(), *, lock: bool = True) -> list[Path]:
    """Check a command's outputs before any work (see the module doc); the output paths, locked.

    ``outputs``: ``(option, path)`` pairs (None paths skipped), e.g. ``[("--record", "take.bvh")]``;
    ``inputs``: ``(option, path)`` pairs or bare paths of the files the command reads. Raises
    :class:`OutputError` (or ``OSError`` for an unwritable folder) naming the output and the clash."""
    from lmm.data.atomic import check_writable

    given = [(option, path, _identity(path)) for option, path in _pairs(inputs)]
    seen = []
    checked = []
    for option, out in _pairs(outputs):
        ident = _identity(out)
        check_output_kind(out, option)
        for in_option, src, src_ident in given:
            if _same(ident, src_ident):
                raise OutputError(f"{out}: {option or 'output'}: would overwrite the input "
                                  f"{_named(in_option, src)}; choose another path")
        for other_option, other, other_ident in seen:
            if _same(ident, other_ident):
                raise OutputError(f"{out}: {option or 'output'}: the same file as the output "
                                  f"{_named(other_option, other)}; give each output its own path")
        check_writable(out)
        seen.append((option, out, ident))
        checked.append(out)
    if lock:
        for option, out, ident in seen:
            lock_output(ident[0], option)
    return checked


# ---- locks --------------------------------------------------------------------------------------------

_held: dict[str, int] = {}   # lock file -> descriptor, for this process


def _lock_folder() -> Path | None:
    """The per-user lock folder, or None where it cannot be made safely (then nothing is locked)."""
    folder = Path(tempfile.gettempdir()) / f"lmm-studio-locks-{os.getuid() if hasattr(os, 'getuid') else 0}"
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
        st = os.lstat(folder)
    except OSError:
        return None
    if not stat.S_ISDIR(st.st_mode) or (hasattr(os, "getuid") and st.st_uid != os.getuid()):
        return None   # someone else's folder, or a link: do not trust it
    return folder


def lock_output(path, option: str = "") -> None:
    """Hold an exclusive lock on the resolved ``path`` for this process, or raise :class:`OutputError`
    naming the process that holds it. Taking a lock this process holds already is a no-op."""
    if fcntl is None:
        return
    folder = _lock_folder()
    if folder is None:
        return
    target = str(resolved(path))
    lock_file = _lock_file(folder, target)
    if lock_file in _held:
        return
    while True:
        fd = os.open(lock_file, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 64, 0).decode("ascii", "replace").split(" ")[0].strip() or "?"
            os.close(fd)
            raise OutputError(f"{path}: {option or 'output'}: being written by another lmm-studio (process "
                              f"{holder}); wait for it to finish or choose another path") from None
        except OSError:   # a file system without locks: go on unlocked
            os.close(fd)
            return
        try:
            same = os.fstat(fd).st_ino == os.stat(lock_file).st_ino
        except FileNotFoundError:
            same = False
        if same:   # not a file its previous holder removed between our open and our lock
            break
        os.close(fd)
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()} {target}\n".encode("utf-8", "surrogateescape"), 0)
    _held[lock_file] = fd


def _lock_file(folder: Path, target: str) -> str:
    return str(folder / (hashlib.sha256(target.encode("utf-8", "surrogateescape")).hexdigest()[:32] + ".lock"))


def release_output(path) -> None:
    """Remove and unlock this process's lock on ``path`` (a stream that was closed), if it holds one."""
    folder = _lock_folder()
    if folder is None or not _held:
        return
    lock_file = _lock_file(folder, str(resolved(path)))
    fd = _held.pop(lock_file, None)
    if fd is not None:
        try:
            os.unlink(lock_file)
        except OSError:
            pass
        os.close(fd)


def release_locks() -> None:
    """Remove and unlock every lock this process holds (the kernel unlocks on exit anyway)."""
    while _held:
        lock_file, fd = _held.popitem()
        try:
            os.unlink(lock_file)
        except OSError:
            pass
        os.close(fd)
