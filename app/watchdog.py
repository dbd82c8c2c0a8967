"""SIGTERM always ends the studio, even when its main thread is stuck inside native code.

Python runs a signal handler only when the main thread next executes Python code; a studio spinning in
dearpygui/ImGui (a layout's ini writer looping on a corrupt table) never does, so ``timeout``'s SIGTERM
was ignored for 16 CPU-minutes. :func:`arm` starts a small watchdog process and points Python's signal
wakeup file descriptor at a pipe to it: the interpreter's C-level handler writes the signal number
there at once, without the GIL. The watchdog then gives the studio ``grace_s`` seconds to shut down
through its own handler (recording and layout saved) and kills it (SIGKILL) if it is still there. It
ends by itself when the studio ends (the pipe closes).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys

_WATCHDOG = r"""
import os, signal, sys, time
fd, parent, grace = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
signal.signal(signal.SIGINT, signal.SIG_IGN)
while True:
    data = os.read(fd, 64)
    if not data:
        sys.exit(0)                  # the studio ended: nothing to watch
    if signal.SIGTERM in data:
        deadline = time.monotonic() + grace
        while time.monotonic() < deadline:
            try:
                os.kill(parent, 0)
            except ProcessLookupError:
                sys.exit(0)
            time.sleep(0.05)
        try:
            os.kill(parent, signal.SIGKILL)
        except ProcessLookupError:
            pass
        sys.exit(0)
"""


def arm(grace_s: float = 10.0):
    """Start the watchdog for this process (see the module doc); the ``Popen``, or None where it cannot
    run (not POSIX, no wakeup fd in this thread)."""
    if not hasattr(os, "pipe2") and not hasattr(os, "pipe"):
        return None
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)          # the C handler must never block on a full pipe
    try:
        proc = subprocess.Popen([sys.executable, "-c", _WATCHDOG, str(read_end), str(os.getpid()), str(grace_s)],
                                pass_fds=(read_end,), stdin=subprocess.DEVNULL, start_new_session=True)
    except OSError:
        os.close(read_end)
        os.close(write_end)
        return None
    os.close(read_end)
    try:
        signal.set_wakeup_fd(write_end, warn_on_full_buffer=False)
    except ValueError:   # not the main thread
        proc.kill()
        os.close(write_end)
        return None
    if signal.getsignal(signal.SIGTERM) in (signal.SIG_DFL, None):
        # a wakeup byte is only written for a signal with a Python handler; the studio installs its own
        signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
    return proc
