"""The database's ranges in the source files' own terms: which file (as the manifest names it), which
frames of that file ``[start, stop)``, tags, mirrored or not, and the mapping between database frames
(the database rate, e.g. 60 fps) and the file's frames (e.g. 30 fps).

The database keeps each range's name (``stem[start:stop]``, the file's frames) and length; the
manifest, when given, adds the file as written in it. A range of ``n`` file frames resampled to ``m``
database frames advances ``step`` file frames per database frame, where the build made
``m = ceil((n - 1 + 1e-9) / step)``, so ``(n - 1) / m <= step <= (n - 1) / (m - 1)``; the step of a
whole number of file frames per second (the build rounds a frame time such as 0.033333 to 30 fps) in
that interval is taken (the upper end when none is), so a mapped frame is exact for the usual
rates and otherwise off by less than one file frame; it is rounded to the nearest file frame.

:func:`manifest_range` turns a selection (file frames, ``stop`` exclusive) into the manifest's
``{"range": [a, b], "tags": [...]}``; a selection that is empty or leaves the range raises
:class:`RangeSelectionError` naming the file.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from lmm.errors import InputError

_NAME = re.compile(r"^(?P<stem>.*)\[(?P<start>-?\d+):(?P<stop>-?\d+)\](?P<mirror> mirrored)?$")


class RangeSelectionError(InputError):
    """A selection of a database range that is empty or outside the range; ``str(e)`` names the file."""


@dataclass(frozen=True)
class RangeInfo:
    index: int                     # the database range
    name: str                      # the database's range name
    file: str                      # the file as the manifest names it (the stem when no manifest is known)
    source_start: int              # the file's frames [source_start, source_stop)
    source_stop: int
    db_start: int                  # the database's frames [db_start, db_stop)
    db_stop: int
    mirrored: bool
    tags: tuple[str, ...]
    step: float                    # file frames per database frame
    fps: float                     # database frames per second

    @property
    def n_frames(self) -> int:
        return self.db_stop - self.db_start

    @property
    def seconds(self) -> float:
        return self.n_frames / self.fps

    @property
    def source_fps(self) -> float:
        """The file's frame rate as the build played it (speed scale included)."""
        return self.fps * self.step

    def contains(self, db_frame: int) -> bool:
        return self.db_start <= int(db_frame) < self.db_stop

    def source_frame(self, db_frame) -> np.ndarray | int:
        """The file frame (rounded) a database frame of this range was resampled at."""
        f = self.source_start + (np.asarray(db_frame, np.float64) - self.db_start) * self.step
        out = np.clip(np.rint(f), self.source_start, self.source_stop - 1).astype(np.int64)
        return int(out) if out.ndim == 0 else out

    def db_frame(self, source_frame) -> np.ndarray | int:
        """The database frame of this range nearest to a file frame (clamped to the range)."""
        f = self.db_start + (np.asarray(source_frame, np.float64) - self.source_start) / max(self.step, 1e-12)
        out = np.clip(np.rint(f), self.db_start, self.db_stop - 1).astype(np.int64)
        return int(out) if out.ndim == 0 else out

    def label(self) -> str:
        return f"{self.file} [{self.source_start}:{self.source_stop}]" + (" mirrored" if self.mirrored else "")


def _step(n_source: int, n_db: int, db_fps: float, speed_scale: float = 1.0) -> float:
    """File frames per database frame of a range of ``n_source`` file frames built into ``n_db``."""
    if n_db <= 1 or n_source == n_db:
        return 1.0
    lo, hi = (n_source - 1) / n_db, (n_source - 1) / (n_db - 1)
    per_fps = speed_scale / db_fps                   # step per file frame per second
    whole = np.arange(np.ceil(lo / per_fps - 1e-9), np.floor(hi / per_fps + 1e-9) + 1)
    return float(whole[-1] * per_fps) if len(whole) else hi


def database_ranges(db, manifest=None) -> list[RangeInfo]:
    """Every range of ``db`` as a :class:`RangeInfo`. ``manifest`` (the :class:`lmm.data.manifest.Manifest`
    the database was built from) names the files as written in it; without it, or when it does not
    describe these ranges, the file is the stem the range is named by."""
    files = _manifest_files(db, manifest)
    speed = float(manifest.speed_scale) if manifest is not None else 1.0
    out = []
    for r in range(db.n_ranges):
        name = db.range_names[r] if r < len(db.range_names) else f"range {r}"
        a, b = int(db.range_starts[r]), int(db.range_stops[r])
        m = _NAME.match(name)
        if m:
            stem, s0, s1 = m.group("stem"), int(m.group("start")), int(m.group("stop"))
        else:   # not a name the build makes: the range's own frames
            stem, s0, s1 = name, 0, b - a
        tags = tuple(db.range_tags[r]) if r < len(db.range_tags) else ()
        out.append(RangeInfo(index=r, name=name, file=files[r] if files else stem, source_start=s0,
                             source_stop=s1, db_start=a, db_stop=b, mirrored=bool(db.range_mirrored[r]),
                             tags=tags, step=_step(s1 - s0, b - a, float(db.fps), speed), fps=float(db.fps)))
    return out


def _manifest_files(db, manifest) -> list[str] | None:
    """The file of every database range in build order (see lmm.data.build.build), or None when the
    manifest does not have this database's number of ranges."""
    if manifest is None:
        return None
    files = []
    copies = 2 if manifest.mirror else 1
    for clip in manifest.clips:
        source = clip.source or str(clip.file)
        files += [source] * (len(clip.ranges or [None]) * copies)
    return files if len(files) == db.n_ranges else None


def range_of_frame(ranges: list[RangeInfo], db_frame: int) -> RangeInfo | None:
    """The range holding a database frame (None when no range does)."""
    starts = np.array([r.db_start for r in ranges])
    i = int(np.searchsorted(starts, int(db_frame), side="right")) - 1
    if 0 <= i < len(ranges) and ranges[i].contains(db_frame):
        return ranges[i]
    return None


def check_selection(info: RangeInfo, start: int, stop: int) -> tuple[int, int]:
    """``(start, stop)`` (file frames, ``stop`` exclusive) when it is a non-empty part of the range, else a
    :class:`RangeSelectionError` naming the file."""
    start, stop = int(start), int(stop)
    where = f"{info.file} [{info.source_start}:{info.source_stop}]"
    if stop <= start:
        raise RangeSelectionError(f"{info.file}: the selection [{start}:{stop}] is empty (pick an end after "
                                  f"its start, in {where})")
    if start < info.source_start or stop > info.source_stop:
        side = "past the end" if stop > info.source_stop else "before the start"
        raise RangeSelectionError(f"{info.file}: the selection [{start}:{stop}] is {side} of the range {where}")
    return start, stop


def manifest_range(info: RangeInfo, start: int, stop: int) -> dict:
    """The manifest entry of a selection of ``info``: ``{"range": [start, stop], "tags": [...]}`` in the
    file's own frames (checked by :func:`check_selection`)."""
    start, stop = check_selection(info, start, stop)
    return {"range": [start, stop], "tags": list(info.tags)}
