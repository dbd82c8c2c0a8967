"""What an interrupted command leaves, removed by the next one, and worker processes that never outlive
their parent.

Every temporary thing the project makes carries the id of the process that made it: atomic writes'
``.NAME.PID.HEX.tmp`` (:mod:`lmm.data.atomic`), streams' ``.NAME.PID.partial`` (:mod:`lmm.data.stream`)
and the build's spill folders ``$TMPDIR/lmm-build-PID-*`` (:mod:`lmm.data.build`). A process killed
with SIGKILL cannot remove them (a SIGTERM'd build left 435-578 MB in ``$TMPDIR`` and a 204-354 MB
``.tmp`` in the cache); the next build removes each one whose process is gone (:func:`remove_stale`).
Build workers ask the kernel to kill them when their parent dies (:func:`die_with_parent`), so they
never wait forever on a queue no one writes, and leave SIGTERM to its default (no traceback).
"""
from __future__ import annotations

import os
import re
import shutil
import signal
import tempfile
from pathlib import Path

#: names of temporary files made beside a target, with the maker's process id
_TEMP_FILE = re.compile(r"^\..+\.(\d+)(?:\.[0-9a-f]{8})?\.(?:tmp|probe|partial)$")
#: the build's spill folders in the temporary folder
SPILL_PREFIX = "lmm-build-"
_SPILL = re.compile(rf"^{SPILL_PREFIX}(\d+)-")


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists (one of another user counts as alive)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def _dead_makers(folder, pattern: re.Pattern, want_dir: bool):
    """Entries of ``folder`` (not below it) named by ``pattern`` (group 1: the maker's process id), of
    this user, a folder or a plain file as ``want_dir`` says, whose maker is gone."""
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return
    uid = os.getuid() if hasattr(os, "getuid") else None
    for entry in entries:
        m = pattern.match(entry.name)
        if m is None or pid_alive(int(m.group(1))):
            continue
        try:
            kind_ok = entry.is_dir(follow_symlinks=False) if want_dir else entry.is_file(follow_symlinks=False)
            if kind_ok and (uid is None or entry.stat(follow_symlinks=False).st_uid == uid):
                yield Path(entry.path)
        except OSError:
            continue


def remove_stale(folder) -> list[Path]:
    """Remove, in ``folder`` (not below it), the temporary files whose maker is gone; the paths removed.
    Files of running processes, and anything not named like our temporaries, are left alone."""
    removed = []
    for path in _dead_makers(folder, _TEMP_FILE, want_dir=False):
        try:
            path.unlink()
            removed.append(path)
        except OSError:
            pass
    return removed


def remove_stale_spills(folder=None) -> list[Path]:
    """Remove the build spill folders (``lmm-build-PID-*``) of processes that are gone."""
    removed = list(_dead_makers(Path(folder or tempfile.gettempdir()), _SPILL, want_dir=True))
    for path in removed:
        shutil.rmtree(path, ignore_errors=True)
    return removed


def spill_folder():
    """A new spill folder for this process (a ``TemporaryDirectory``), named so a later build can tell
    whether its maker still runs."""
    return tempfile.TemporaryDirectory(prefix=f"{SPILL_PREFIX}{os.getpid()}-", ignore_cleanup_errors=True)


def die_with_parent() -> None:
    """In a worker process: SIGKILL when the parent dies (Linux ``PR_SET_PDEATHSIG``), SIGTERM back to
    its default (the parent's ``Pool.terminate`` ends it without a traceback), SIGINT ignored (the
    parent handles Ctrl-C and stops the pool)."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)   # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):
        pass   # not Linux: the pool's own pipes end the worker when the parent closes them


def processes_using_tmpdir(tmp) -> list[int]:
    """Processes (but this one) whose environment names ``TMPDIR=tmp``: what is still running of a build
    started with a private temporary folder (Linux ``/proc``; empty elsewhere). For tests and benchmarks
    that check that no worker outlives its build."""
    marker = f"TMPDIR={tmp}".encode()
    pids = []
    for entry in Path("/proc").glob("[0-9]*"):
        if int(entry.name) != os.getpid():
            try:
                if marker in (entry / "environ").read_bytes().split(b"\0"):
                    pids.append(int(entry.name))
            except OSError:
                pass
    return pids
