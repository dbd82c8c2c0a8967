"""A dependency-free text progress bar with rate and ETA (stderr, redrawn in place on a TTY)."""
from __future__ import annotations

import sys
import time


class Progress:
    def __init__(self, total: int, label: str = "", stream=None, min_interval_s: float = 0.2, enabled: bool = True):
        self.total = max(int(total), 1)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.count = 0
        self.start = time.perf_counter()
        self._last = 0.0
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.min_interval_s = min_interval_s if self._tty else max(min_interval_s, 5.0)
        self.postfix = ""

    def eta_s(self) -> float:
        elapsed = time.perf_counter() - self.start
        return elapsed / self.count * (self.total - self.count) if self.count else float("nan")

    def update(self, n: int = 1, postfix: str | None = None) -> None:
        self.count = min(self.count + n, self.total)
        if postfix is not None:
            self.postfix = postfix
        now = time.perf_counter()
        if self.enabled and (now - self._last >= self.min_interval_s or self.count == self.total):
            self._last = now
            self._draw(now)

    def _draw(self, now: float) -> None:
        frac = self.count / self.total
        width = 28
        bar = "#" * int(frac * width) + "-" * (width - int(frac * width))
        elapsed = now - self.start
        eta = self.eta_s()
        eta_txt = f"{eta:6.0f}s" if eta == eta else "     ?"
        line = f"{self.label} [{bar}] {frac * 100:5.1f}% {self.count}/{self.total} {elapsed:6.1f}s eta {eta_txt} {self.postfix}"
        if self._tty:
            self.stream.write("\r" + line[:200].ljust(80))
            if self.count == self.total:
                self.stream.write("\n")
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled and self.count < self.total and self._tty:
            self.stream.write("\n")
            self.stream.flush()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class ProgressCallback:
    """A ``progress(done, total, label)`` callback (the one ``load_or_build`` and ``MotionIndex.build``
    take) that opens a :class:`Progress` bar on its first call and advances it one step per call;
    ``skip_start`` ignores the calls with ``done == 0`` (a builder announcing the total). Nothing is drawn
    when ``quiet``. Use as a context manager, or call :meth:`close`."""

    def __init__(self, label: str, quiet: bool = False, skip_start: bool = False):
        self.label, self.quiet, self.skip_start = label, quiet, skip_start
        self.bar: Progress | None = None

    def __call__(self, done, total, label) -> None:
        if self.quiet:
            return
        if self.bar is None:
            self.bar = Progress(total, self.label)
        if done or not self.skip_start:
            self.bar.update(1, postfix=label)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()

    def __enter__(self) -> "ProgressCallback":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
