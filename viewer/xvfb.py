"""Start a private Xvfb virtual display, for windows on machines without a screen (tests, benchmarks, CI)."""
from __future__ import annotations

import os
import shutil
import subprocess
import time


class XvfbUnavailable(RuntimeError):
    pass


class Xvfb:
    """A running ``Xvfb`` on a display number it picks itself (``-displayfd``); use as a context manager.

    ``display`` is the ``:N`` string for ``DISPLAY``; ``env()`` returns os.environ with it set.
    """

    def __init__(self, screen: str = "1920x1080x24", timeout_s: float = 15.0):
        exe = shutil.which("Xvfb")
        if exe is None:
            raise XvfbUnavailable("Xvfb is not installed (apt-get install xvfb)")
        read_fd, write_fd = os.pipe()
        self.proc = subprocess.Popen([exe, "-displayfd", str(write_fd), "-screen", "0", screen, "-nolisten", "tcp"],
                                     pass_fds=(write_fd,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(write_fd)
        number = b""
        deadline = time.monotonic() + timeout_s
        os.set_blocking(read_fd, False)
        while time.monotonic() < deadline and not number.endswith(b"\n") and self.proc.poll() is None:
            try:
                number += os.read(read_fd, 16)
            except BlockingIOError:
                time.sleep(0.05)
        os.close(read_fd)
        if not number.strip().isdigit():
            self.stop()
            raise XvfbUnavailable("Xvfb did not start")
        self.display = f":{number.decode().strip()}"

    def env(self, **extra) -> dict:
        return dict(os.environ, DISPLAY=self.display, **extra)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()

    def __enter__(self) -> "Xvfb":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
