"""A studio recording's files: where one recording writes (a BVH per controller and the input CSV, never
over an existing file), the recording in progress, and what it left on disk
(:meth:`app.session.Session.start_recording` / ``stop_recording`` drive them)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


def recording_paths(base, which: tuple[str, ...]) -> dict[str, Path]:
    """Files written by one recording: a BVH per controller and the input CSV.

    ``base`` is what the user picked (``take.bvh`` or ``take``): one controller writes ``take.bvh``,
    several write ``take_mm.bvh`` / ``take_lmm.bvh``; the input goes to ``take_input.csv``.
    """
    base = Path(base)
    stem = base.name[:-4] if base.name.lower().endswith(".bvh") else base.name
    folder = base.parent
    out = {}
    for name in which:
        out[name] = folder / (f"{stem}.bvh" if len(which) == 1 else f"{stem}_{name}.bvh")
    out["input"] = folder / f"{stem}_input.csv"
    return out


def session_path_of(paths: dict) -> Path:
    """The session file beside a recording's files (:mod:`app.session_log`): ``take_input.csv`` ->
    ``take.lmmsession``."""
    from lmm.session.schema import SUFFIX

    name = Path(paths["input"]).name
    stem = name[: -len("_input.csv")] if name.endswith("_input.csv") else Path(name).stem
    return Path(paths["input"]).with_name(stem + SUFFIX)


def _taken(paths: dict) -> bool:
    return any(p.exists() for p in [*paths.values(), session_path_of(paths)])


def free_recording_paths(base, which: tuple[str, ...]) -> dict[str, Path]:
    """:func:`recording_paths` of ``base``, or, when any of those files exists, of the first numbered
    base none of whose files (nor its session file) exists (``take.bvh`` -> ``take_001.bvh``, ``take_002.bvh``, ...; one
    number for all files of the recording). A recording never overwrites a file."""
    paths = recording_paths(base, which)
    if not _taken(paths):
        return paths
    base = Path(base)
    stem = base.name[:-4] if base.name.lower().endswith(".bvh") else base.name
    number = 1
    while True:
        paths = recording_paths(base.parent / f"{stem}_{number:03d}.bvh", which)
        if not _taken(paths):
            return paths
        number += 1


@dataclass
class RecordingResult:
    """What :meth:`Session.stop_recording` left on disk."""
    paths: dict[str, Path]   # controller name (and "input") -> file written; empty when nothing was written
    frames: int
    seconds: float
    message: str             # one line for the studio's status bar
    session: Path | None = None   # the session file that replays it (lmm-studio replay), when one was kept


@dataclass
class Recording:
    """A recording in progress: one streaming BVH per controller and the input CSV, checked from the
    start (so a folder that cannot be written fails at once). Each file appears with its first flushed
    frames (:mod:`lmm.data.stream`), so a recording that gets no frame leaves no file."""
    paths: dict[str, Path]
    recorders: dict          # controller name -> lmm.data.recording.BVHRecorder
    input_writer: object     # lmm.data.inputs.InputCsvWriter
    start_tick: int
    frames: int = 0
    session: Path | None = None   # its session file (app.session_log), or None when it could not be kept

    def writers(self) -> dict:
        """Controller name (and "input") -> its writer."""
        out = dict(self.recorders)
        if self.input_writer is not None:
            out["input"] = self.input_writer
        return out

    def close(self) -> list[str]:
        """Close every file, even when one fails (e.g. a full disk); returns one line per failure."""
        errors = []
        for w in self.writers().values():
            try:
                w.close()
            except OSError as e:
                errors.append(str(e))
        return errors

    def written(self) -> dict[str, Path]:
        """The files that exist (a file appears with its first flushed frames)."""
        return {name: self.paths[name] for name, w in self.writers().items() if w.exists}
