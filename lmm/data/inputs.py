"""Input sources: recorded input logs (CSV), built-in scenarios, and a streaming CSV writer.

An input log is a table of rows ``time,left_x,left_y,right_x,right_y,walk,strafe`` (optionally a
``camera_azimuth`` column, radians); each row holds from its time until the next row's time, and the
last row holds forever. Sticks are in [-1, 1]; ``walk``/``strafe`` are 0/1 (``true``/``false`` also read).

Built-in scenarios (``builtin:NAME``) are deterministic logs for tests, evaluation and benchmarks:
``circle``, ``zigzag``, ``stop-and-go``, ``strafe``, ``turns``, ``steps`` and ``random:SEED``.

Every problem in a log raises :class:`InputLogError` (an :class:`lmm.errors.InputError`) naming the file,
the 1-based line and the column. Accepted ranges and costs are checked before the work:
``MAX_INPUT_SECONDS`` for times, ``MAX_INPUT_LOG_BYTES`` for the file (read no further).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lmm import errors
from lmm.data.atomic import write_text_atomic
from lmm.data.reading import NotRegularFileError, ascii_float, ascii_int, open_regular
from lmm.data.stream import BufferedStreamWriter, StreamFile

COLUMNS = ("time", "left_x", "left_y", "right_x", "right_y", "walk", "strafe")
OPTIONAL_COLUMNS = ("camera_azimuth",)
BUILTIN_SCENARIOS = ("circle", "zigzag", "stop-and-go", "strafe", "turns", "steps", "random:SEED")
BUILTIN_RATE_HZ = 60.0
DEFAULT_BUILTIN_SECONDS = 60.0
_TIME_EPS = 1e-9  # a query a rounding error before a row's time still gets that row

#: Longest run (s) the program accepts: ``run --seconds``, a log's times, a built-in's length. A day of
#: simulated time at the highest accepted tick rate (1000 Hz, see app/commands/run.py) is 8.64e7 ticks,
#: counted exactly in an int and timed to ~1e-8 s in float64; beyond it a headless run takes days at its
#: measured speed and ``seconds * fps`` stops being a sane tick count (1e308 overflows).
MAX_INPUT_SECONDS = 86400.0
#: Most lines in an input log, counted before parsing. Our writer adds a row only when the input changes,
#: at most one per tick: a million rows is 4.6 h of input changing at every 60 Hz tick. Parsing costs
#: about 300 bytes per row (a Python float per cell, the line's string), so at most ~0.3 GB.
MAX_INPUT_LOG_LINES = 1_000_000
#: Largest input log read (bytes): a million rows of about 60 bytes (the writer's shortest-float cells).
MAX_INPUT_LOG_BYTES = 64 * 1024 * 1024
#: Largest |camera_azimuth| (rad) accepted: 160,000 turns of the camera; float64 still resolves 1e-10 rad.
MAX_CAMERA_AZIMUTH_RAD = 1e6


@dataclass
class InputState:
    """One tick of user input. Sticks in [-1, 1]; y up on the stick means 'away from the camera'."""
    left_x: float = 0.0
    left_y: float = 0.0
    right_x: float = 0.0
    right_y: float = 0.0
    walk: bool = False
    strafe: bool = False
    camera_azimuth: float = 0.0  # radians, rotation of the camera about +Y (0: camera looks along +Z)

    def copy(self) -> "InputState":
        return InputState(**self.__dict__)


class InputLogError(errors.InputError):
    """A bad input log or input spec. ``str(e)`` is ``'<file>: line L, column C (<name>): <message>'``."""

    def __init__(self, message: str, path=None, line: int | None = None, column: int | None = None,
                 column_name: str | None = None):
        self.message, self.path, self.line, self.column, self.column_name = message, path, line, column, column_name
        where = []
        if line is not None:
            where.append(f"line {line}")
        if column is not None:
            where.append(f"column {column}" + (f" ({column_name})" if column_name else ""))
        prefix = f"{path}: " if path is not None else ""
        super().__init__(prefix + (", ".join(where) + ": " if where else "") + message)


InputError = InputLogError  # this module's name for it before lmm.errors existed (app/actions.py, tests)


@dataclass
class InputLog:
    """A piecewise-constant input signal. Arrays are (R,), ``times`` non-decreasing."""
    times: np.ndarray
    left_x: np.ndarray
    left_y: np.ndarray
    right_x: np.ndarray
    right_y: np.ndarray
    walk: np.ndarray
    strafe: np.ndarray
    camera_azimuth: np.ndarray
    name: str = "input"

    @property
    def n_rows(self) -> int:
        return int(self.times.shape[0])

    @property
    def duration(self) -> float:
        return float(self.times[-1]) if self.n_rows else 0.0

    def row_at(self, t: float) -> int:
        return max(int(np.searchsorted(self.times, t + _TIME_EPS, side="right")) - 1, 0)

    def at(self, t: float) -> InputState:
        """The input held at time ``t`` (s); before the first row, the first row."""
        i = self.row_at(t)
        return InputState(float(self.left_x[i]), float(self.left_y[i]), float(self.right_x[i]),
                          float(self.right_y[i]), bool(self.walk[i]), bool(self.strafe[i]),
                          float(self.camera_azimuth[i]))

    __call__ = at

    @classmethod
    def from_rows(cls, rows, name: str = "input") -> "InputLog":
        """From (time, InputState) pairs."""
        rows = list(rows)
        col = lambda f: np.array([f(s) for _, s in rows], dtype=np.float64)  # noqa: E731
        return cls(np.array([t for t, _ in rows], dtype=np.float64), col(lambda s: s.left_x),
                   col(lambda s: s.left_y), col(lambda s: s.right_x), col(lambda s: s.right_y),
                   col(lambda s: s.walk).astype(bool), col(lambda s: s.strafe).astype(bool),
                   col(lambda s: s.camera_azimuth), name)


# ---------------------------------------------------------------------------------------------
# CSV
# ---------------------------------------------------------------------------------------------

def _fmt(v: float) -> str:
    """Shortest text that reads back to the same float (so a replayed log is bit-exact)."""
    v = float(v) + 0.0
    return repr(v) if not v.is_integer() else str(int(v)) if abs(v) < 1e15 else repr(v)


def format_row(t: float, s: InputState, with_camera: bool) -> str:
    cells = [_fmt(t), _fmt(s.left_x), _fmt(s.left_y), _fmt(s.right_x), _fmt(s.right_y),
             "1" if s.walk else "0", "1" if s.strafe else "0"]
    if with_camera:
        cells.append(_fmt(s.camera_azimuth))
    return ",".join(cells) + "\n"


def header_line(with_camera: bool) -> str:
    return ",".join(COLUMNS + (OPTIONAL_COLUMNS if with_camera else ())) + "\n"


#: every byte sequence str.splitlines() ends a line at (what parse_input_csv splits on), as UTF-8: LF,
#: CR (alone; CRLF counts once), VT, FF, FS, GS, RS, NEL and the Unicode line and paragraph separators
_LINE_BREAKS = (b"\n", b"\r", b"\x0b", b"\x0c", b"\x1c", b"\x1d", b"\x1e", b"\xc2\x85", b"\xe2\x80\xa8",
                b"\xe2\x80\xa9")


def count_lines(data: bytes) -> int:
    """The lines :func:`parse_input_csv` will see in ``data``, counted on the bytes before decoding, so
    the line limit holds whatever separates the rows (a CR-only log of 4.8 M rows got past a ``\\n`` count)."""
    return sum(data.count(b) for b in _LINE_BREAKS) - data.count(b"\r\n") + 1


def load_input_csv(path) -> InputLog:
    path = Path(path)
    try:
        with open_regular(path, "input log") as f:   # a FIFO or a device is refused, never waited on
            data = f.read(MAX_INPUT_LOG_BYTES + 1)  # never more than the limit in memory
        if len(data) > MAX_INPUT_LOG_BYTES:
            raise InputError(f"input log larger than {MAX_INPUT_LOG_BYTES // (1024 * 1024)} MB "
                             f"(MAX_INPUT_LOG_BYTES; over a million input changes)", path)
        lines = count_lines(data)
        if lines > MAX_INPUT_LOG_LINES:
            raise InputError(f"input log has {lines} lines, more than {MAX_INPUT_LOG_LINES} "
                             f"(MAX_INPUT_LOG_LINES)", path)
        text = data.decode("utf-8-sig")
        del data
    except NotRegularFileError as e:
        raise InputError(str(e).split(": ", 1)[-1], path) from None
    except FileNotFoundError:
        raise InputError("no such input file", path) from None
    except IsADirectoryError:
        raise InputError("is a folder, not an input log", path) from None
    except OSError as e:
        raise InputError(f"cannot read the input file ({e.strerror})", path) from None
    except UnicodeDecodeError as e:
        raise InputError(f"not UTF-8 text (byte {e.start})", path) from None
    return parse_input_csv(text, path)


def parse_input_csv(text: str, path="<input>") -> InputLog:
    lines = text.splitlines()
    first = next((i for i, ln in enumerate(lines) if ln.strip()), None)
    if first is None:
        raise InputError(f"empty input log: expected the header {','.join(COLUMNS)}", path, 1)
    header = [h.strip() for h in lines[first].split(",")]
    hline = first + 1
    for c, name in enumerate(header, 1):
        if name not in COLUMNS and name not in OPTIONAL_COLUMNS:
            raise InputError(f"unknown column {name!r} (expected {','.join(COLUMNS)}"
                             f" and optionally {','.join(OPTIONAL_COLUMNS)})", path, hline, c, name or None)
        if header.index(name) != c - 1:
            raise InputError(f"column {name!r} appears twice", path, hline, c, name)
    for name in COLUMNS:
        if name not in header:
            raise InputError(f"missing column {name!r}: the header must name {','.join(COLUMNS)}",
                             path, hline, len(header) + 1, name)
    values = {name: [] for name in header}
    last_t, last_line = None, None
    for i in range(first + 1, len(lines)):
        raw = lines[i]
        if not raw.strip():
            continue
        line = i + 1
        cells = raw.split(",")
        if len(cells) != len(header):
            c = min(len(cells), len(header)) + 1  # the first missing (or first extra) value
            name = header[c - 1] if c - 1 < len(header) else None
            raise InputError(f"expected {len(header)} values, found {len(cells)}", path, line, c, name)
        for c, (name, cell) in enumerate(zip(header, cells), 1):
            cell = cell.strip()
            if name in ("walk", "strafe"):
                low = cell.lower()
                if low in ("1", "true", "1.0"):
                    v = 1.0
                elif low in ("0", "false", "0.0"):
                    v = 0.0
                else:
                    raise InputError(f"expected 0 or 1, found {cell[:20]!r}", path, line, c, name)
            else:
                try:
                    v = ascii_float(cell)
                except ValueError:
                    raise InputError(f"expected a number, found {cell[:20]!r}", path, line, c, name) from None
                if not math.isfinite(v):
                    raise InputError(f"expected a finite number, found {cell[:20]!r}", path, line, c, name)
                if name in ("left_x", "left_y", "right_x", "right_y"):
                    if abs(v) > 1.0 + 1e-6:
                        raise InputError(f"stick value {cell[:20]} is outside [-1, 1]", path, line, c, name)
                    v = min(max(v, -1.0), 1.0)
                if name == "camera_azimuth" and abs(v) > MAX_CAMERA_AZIMUTH_RAD:
                    raise InputError(f"camera azimuth {cell[:20]} rad is outside +-{MAX_CAMERA_AZIMUTH_RAD:g} "
                                     f"(MAX_CAMERA_AZIMUTH_RAD)", path, line, c, name)
                if name == "time":
                    if not 0.0 <= v <= MAX_INPUT_SECONDS:
                        raise InputError(f"time {cell[:20]} is outside [0, {MAX_INPUT_SECONDS:g}] s "
                                         f"(MAX_INPUT_SECONDS, one day)", path, line, c, name)
                    if last_t is not None and v < last_t:
                        raise InputError(f"time goes backwards: {cell} after {last_t!r} on line {last_line}",
                                         path, line, c, name)
                    last_t, last_line = v, line
            values[name].append(v)
    if not values["time"]:
        raise InputError("no data rows after the header", path, hline + 1)
    arr = {k: np.asarray(v, dtype=np.float64) for k, v in values.items()}
    cam = arr.get("camera_azimuth", np.zeros_like(arr["time"]))
    return InputLog(arr["time"], arr["left_x"], arr["left_y"], arr["right_x"], arr["right_y"],
                    arr["walk"] > 0.5, arr["strafe"] > 0.5, cam, name=str(path))


def save_input_csv(path, log: InputLog) -> None:
    with_camera = bool(np.any(log.camera_azimuth != 0.0))
    parts = [header_line(with_camera)]
    for i in range(log.n_rows):
        state = InputState(float(log.left_x[i]), float(log.left_y[i]), float(log.right_x[i]),
                           float(log.right_y[i]), bool(log.walk[i]), bool(log.strafe[i]),
                           float(log.camera_azimuth[i]))
        parts.append(format_row(log.times[i], state, with_camera))
    write_text_atomic(path, "".join(parts))


class InputCsvWriter(BufferedStreamWriter):
    """Streams input rows to a CSV log while running; writes a row only when the input changes.

    Crash-safe like the BVH recorder (:class:`lmm.data.stream.StreamFile`): rows are appended whole
    (and fsynced) at least every ``flush_interval_s`` seconds of wall time; the file appears with its
    first rows and is a valid log whenever it exists; a full disk keeps the rows of the last good flush.
    """

    def __init__(self, path, with_camera: bool = True, flush_interval_s: float = 0.5, clock=None,
                 overwrite: bool = True):
        import time as _time

        self.path = Path(path)
        self.with_camera = with_camera
        self.flush_interval_s = flush_interval_s
        self._clock = clock or _time.monotonic
        self._stream = StreamFile(self.path, header_line(with_camera).encode("utf-8"), overwrite=overwrite,
                                  unit="rows")
        self._last: InputState | None = None
        self._pending: list[str] = []
        self._last_flush = self._clock()
        self.rows = 0

    def write(self, t: float, state: InputState) -> None:
        if self._last is None or state != self._last:
            self._pending.append(format_row(t, state, self.with_camera))
            self._last = state.copy()
            self.rows += 1
        self._flush_if_due()

    def _encode(self, pending: list) -> bytes:
        return "".join(pending).encode("utf-8")


# ---------------------------------------------------------------------------------------------
# built-in scenarios
# ---------------------------------------------------------------------------------------------

def _stick(angle, magnitude=1.0):
    """Stick deflection for a direction ``angle`` (radians, 0 = up/away from camera, positive = right)."""
    return magnitude * np.sin(angle), magnitude * np.cos(angle)


def _tabulate(name, seconds, fn) -> InputLog:
    n = int(math.ceil(seconds * BUILTIN_RATE_HZ)) + 1
    times = np.arange(n) * (1.0 / BUILTIN_RATE_HZ)
    lx, ly, rx, ry, walk, strafe = fn(times)
    z = np.zeros(n)
    b = lambda a: np.broadcast_to(np.asarray(a), (n,)).astype(np.float64)  # noqa: E731
    return InputLog(times, b(lx), b(ly), b(rx), b(ry), b(walk) > 0.5, b(strafe) > 0.5, z, name=f"builtin:{name}")


def _circle(t):
    angle = 2 * np.pi * t / 8.0  # one lap of the stick every 8 s
    lx, ly = _stick(angle)
    walk = (t // 12.0) % 2 == 1  # run 12 s, walk 12 s
    return lx, ly, 0.0, 0.0, walk, 0.0


def _zigzag(t):
    side = np.where((t // 1.5) % 2 == 0, 1.0, -1.0)  # alternate every 1.5 s
    lx, ly = _stick(side * np.radians(60.0))
    walk = (t // 15.0) % 2 == 1
    return lx, ly, 0.0, 0.0, walk, 0.0


def _stop_and_go(t):
    # 8 s cycle: run 2.5 s, stop 1.5 s, walk 2.5 s, stop 1.5 s; the heading turns 90 deg every cycle
    phase = t % 8.0
    heading = np.radians(90.0) * (t // 8.0)
    moving = (phase < 2.5) | ((phase >= 4.0) & (phase < 6.5))
    lx, ly = _stick(heading, np.where(moving, 1.0, 0.0))
    walk = (phase >= 4.0)
    return lx, ly, 0.0, 0.0, walk, 0.0


def _strafe(t):
    # facing fixed to the camera; the left stick visits forward, right, back, left, diagonals, 2 s each
    dirs = np.radians([0.0, 90.0, 180.0, -90.0, 45.0, -135.0, 135.0, -45.0])
    k = (t // 2.0).astype(int) % len(dirs)
    stop = (t % 20.0) >= 16.0  # and stands still for 4 s of every 20
    lx, ly = _stick(dirs[k], np.where(stop, 0.0, 1.0))
    walk = (t // 20.0) % 2 == 1
    return lx, ly, 0.0, 0.0, walk, 1.0


def _turns(t):
    # sharp 180 degree reversals and 90 degree turns every 2 s (forced-search material)
    dirs = np.radians([0.0, 180.0, 90.0, -90.0, 0.0, 135.0])
    k = (t // 2.0).astype(int) % len(dirs)
    lx, ly = _stick(dirs[k])
    walk = (t // 24.0) % 2 == 1
    return lx, ly, 0.0, 0.0, walk, 0.0


def _steps(t):
    # responsiveness: a 16 s cycle of steps in the stick: stand 3 s, run forward 3 s, reverse (180 degrees)
    # 3 s, turn 90 degrees 3 s, stop and stand 4 s
    phase = t % 16.0
    dirs = np.radians(np.array([0.0, 0.0, 180.0, 270.0, 0.0]))
    k = np.searchsorted([3.0, 6.0, 9.0, 12.0], phase, side="right")
    moving = (k >= 1) & (k <= 3)
    lx, ly = _stick(dirs[k], np.where(moving, 1.0, 0.0))
    return lx, ly, 0.0, 0.0, 0.0, 0.0


def _random(seed: int, seconds: float) -> InputLog:
    """Random segments of 0.3-3 s: stick direction/magnitude (sometimes idle), walk and strafe flags.

    Segments are drawn one after another, so a longer run starts with the same input as a shorter one.
    """
    rng = np.random.default_rng(seed)
    rows = []
    t = 0.0
    heading = 0.0
    while t <= seconds:
        u = rng.random()
        if u < 0.15:
            mag = 0.0
        elif u < 0.3:
            mag = float(rng.uniform(0.3, 1.0))
        else:
            mag = 1.0
        heading = heading + float(rng.choice([-1.0, 1.0])) * float(rng.uniform(0.0, np.pi)) \
            if rng.random() < 0.8 else float(rng.uniform(-np.pi, np.pi))
        walk = bool(rng.random() < 0.35)
        strafe = bool(rng.random() < 0.2)
        lx, ly = _stick(heading, mag)
        rx, ry = (0.0, 0.0)
        if strafe and rng.random() < 0.5:
            rx, ry = _stick(float(rng.uniform(-np.pi, np.pi)))
        rows.append((round(t * BUILTIN_RATE_HZ) / BUILTIN_RATE_HZ,
                     InputState(float(lx), float(ly), float(rx), float(ry), walk, strafe, 0.0)))
        t += float(rng.uniform(0.3, 3.0))
    log = InputLog.from_rows(rows, name=f"builtin:random:{seed}")
    return log


_TABLE = {"circle": _circle, "zigzag": _zigzag, "stop-and-go": _stop_and_go, "strafe": _strafe, "turns": _turns,
          "steps": _steps}


def builtin_names(random_seeds=(1,)) -> list[str]:
    """Concrete scenario names, e.g. for running all of them."""
    return [n for n in BUILTIN_SCENARIOS if n != "random:SEED"] + [f"random:{s}" for s in random_seeds]


def builtin(name: str, seconds: float | None = None) -> InputLog:
    """The built-in scenario ``name`` (without the ``builtin:`` prefix) covering ``seconds``."""
    seconds = DEFAULT_BUILTIN_SECONDS if seconds is None else float(seconds)
    if not 0.0 <= seconds <= MAX_INPUT_SECONDS:  # NaN fails too
        raise InputError(f"built-in scenario {name!r}: length {seconds!r} s is outside "
                         f"[0, {MAX_INPUT_SECONDS:g}] (MAX_INPUT_SECONDS, one day)")
    if name.startswith("random:"):
        seed_text = name[len("random:"):]
        try:
            seed = ascii_int(seed_text)
            if seed < 0:
                raise ValueError
        except ValueError:
            raise InputError(f"built-in scenario 'random:SEED' needs a non-negative integer seed, "
                             f"got {seed_text!r}") from None
        return _random(seed, seconds)
    if name not in _TABLE:
        raise InputError(f"unknown built-in input {name!r} (known: {', '.join(BUILTIN_SCENARIOS)})")
    return _tabulate(name, seconds, _TABLE[name])


def open_input(spec: str, seconds: float | None = None) -> InputLog:
    """``builtin:NAME`` or the path of a CSV input log."""
    spec = str(spec)
    if spec.startswith("builtin:"):
        return builtin(spec[len("builtin:"):], seconds)
    return load_input_csv(spec)
