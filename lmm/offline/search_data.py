"""The takes that motion search is trained and evaluated on: a folder of BVH files reduced to pose-window
frames (:mod:`lmm.motion_search.windows`), their action labels and the held-out split (numpy only).

* **Label**: the file name's leading letters (``fallAndGetUp2_subject3.bvh`` -> ``fallAndGetUp``,
  ``walk4_subject1.bvh`` -> ``walk``), the action of a LAFAN1 take; a name without leading letters is
  its own label.
* **Split**: the last :data:`HELD_OUT_FRACTION` of every take (in resampled frames) is held out: queries
  are cut only from there, and training windows only from the frames before it, so no training window
  shares a frame with a query. Every take keeps its label in both parts (LAFAN1 has a single ``walk``
  and a single ``push`` take, so holding out whole takes would leave those labels untrained).
* **Cache**: the frames of a folder are cached in ``search/frames-<key>.npz`` under the cache folder
  (:func:`lmm.data.cache.default_cache_dir`), the key a hash of the files' paths, sizes and
  modification times and of the window representation, written atomically.
"""
from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lmm.errors import InputError
from lmm.motion_search import windows as W

HELD_OUT_FRACTION = 0.2
#: Bump when the frame features or resampling change: old caches are then ignored.
REPRESENTATION_VERSION = 1
#: The 27 shared LAFAN1 takes, beside the repository (``../shared/data/lafan1``) or inside it.
_REPO = Path(__file__).resolve().parents[2]
DEFAULT_DATA_DIR = next((p for p in (_REPO / "shared" / "data" / "lafan1", _REPO.parent / "shared" / "data" / "lafan1")
                         if p.is_dir()), _REPO.parent / "shared" / "data" / "lafan1")


class SearchDataError(InputError):
    """A folder that cannot be searched or trained on; the message names it."""


def action_label(path) -> str:
    """The action of a take from its file name's leading letters (see the module doc)."""
    stem = Path(path).name.split(".")[0]
    m = re.match(r"[A-Za-z]+", stem)
    return m.group(0) if m else stem


@dataclass
class Take:
    """One file's resampled key-joint frames (:data:`lmm.motion_search.windows.WINDOW_FPS`)."""
    file: str           # relative to the folder
    label: str
    file_fps: float
    n_file_frames: int
    frames: np.ndarray  # (n, FRAME_DIM) float32

    @property
    def held_out_start(self) -> int:
        """First held-out resampled frame: queries start at or after it, training ends before it."""
        return int(round(len(self.frames) * (1.0 - HELD_OUT_FRACTION)))

    @property
    def n_windows(self) -> int:
        return max(0, len(self.frames) - W.WINDOW_FRAMES + 1)


def bvh_files(folder) -> list[Path]:
    """Every ``.bvh`` (or ``.bvh.gz``) file under ``folder`` (recursively), sorted; SearchDataError if none."""
    folder = Path(folder)
    if not folder.is_dir():
        raise SearchDataError(f"{folder}: not a folder" + (" (the shared LAFAN1 takes are expected beside the "
                              "repository; name a folder of BVH takes with --data)" if folder == DEFAULT_DATA_DIR else ""))
    files = sorted(p for p in folder.rglob("*") if p.name.lower().endswith((".bvh", ".bvh.gz")) and p.is_file())
    if not files:
        raise SearchDataError(f"{folder}: no .bvh or .bvh.gz files in this folder")
    return files


def folder_key(folder, files: list[Path]) -> str:
    h = hashlib.sha256()
    h.update(json.dumps([REPRESENTATION_VERSION, W.WINDOW_FPS, W.WINDOW_FRAMES, W.FRAME_DIM]).encode())
    for p in files:
        st = p.stat()
        h.update(f"{p.relative_to(folder).as_posix()}|{st.st_size}|{st.st_mtime_ns}\n".encode())
    return h.hexdigest()[:24]


def load_takes(folder=None, cache: bool = True, log=None) -> list[Take]:
    """The takes of ``folder`` (default: :data:`DEFAULT_DATA_DIR`), from the cache when it is current.
    A file that cannot be read or whose key joints cannot be matched raises its one-line error (naming
    the file); a take shorter than one window is kept (it has no windows)."""
    from lmm.data.cache import default_cache_dir

    folder = Path(folder) if folder is not None else DEFAULT_DATA_DIR
    files = bvh_files(folder)
    key = folder_key(folder, files)
    cache_path = default_cache_dir() / "search" / f"frames-{key}.npz"
    if cache and cache_path.is_file():
        try:
            return _read_cache(cache_path)
        except Exception:  # noqa: BLE001 - a damaged cache is rebuilt, never trusted
            pass
    from lmm.data import bvh

    takes = []
    for i, p in enumerate(files):
        rel = p.relative_to(folder).as_posix()
        if log:
            log(f"reading {rel} ({i + 1}/{len(files)})")
        tf = W.take_frames(bvh.load(p), str(p))
        takes.append(Take(rel, action_label(rel), tf.file_fps, tf.n_file_frames, tf.frames))
    if cache:
        _write_cache(cache_path, takes)
    return takes


def _write_cache(path: Path, takes: list[Take]) -> None:
    from lmm.data import archive

    meta = [{"file": t.file, "label": t.label, "file_fps": t.file_fps, "n_file_frames": t.n_file_frames,
             "n": len(t.frames)} for t in takes]
    frames = np.concatenate([t.frames for t in takes]) if takes else np.zeros((0, W.FRAME_DIM), np.float32)
    archive.write(path, {"frames": frames.astype(np.float32)}, meta)


def _read_cache(path: Path) -> list[Take]:
    from lmm.data import archive

    with archive.read(path, what="search frames cache") as r:
        r.refuse_unknown({"frames"})
        meta = r.metadata()
        frames = r.array("frames")
    out, start = [], 0
    for m in meta:
        out.append(Take(m["file"], m["label"], float(m["file_fps"]), int(m["n_file_frames"]),
                        frames[start:start + m["n"]]))
        start += m["n"]
    if start != len(frames):
        raise ValueError("cache frames do not add up")
    return out


def training_frames(takes: list[Take]) -> list[np.ndarray]:
    """The frames before each take's held-out part (what training may see)."""
    return [t.frames[: t.held_out_start] for t in takes]


def labels_of(takes: list[Take]) -> list[str]:
    """The distinct labels, sorted (the classifier's classes)."""
    return sorted({t.label for t in takes})


def warped_segments(frames: np.ndarray, starts, speeds, length: int = W.WINDOW_FRAMES) -> np.ndarray:
    """``(n, length, FRAME_DIM)`` windows of ``frames`` played at ``speeds`` (1.25 = 25 % faster): window
    ``i`` covers source frames ``starts[i] .. starts[i] + (length - 1) * speeds[i]``, linearly
    interpolated, with the velocity and yaw-rate channels multiplied by the speed (the same motion done
    faster moves faster). Source times past the end are clamped to the last frame."""
    starts = np.asarray(starts, np.float64).reshape(-1, 1)
    speeds = np.asarray(speeds, np.float64).reshape(-1, 1)
    t = starts + np.arange(length)[None, :] * speeds
    t = np.clip(t, 0.0, len(frames) - 1)
    i0 = np.floor(t).astype(np.int64)
    i1 = np.minimum(i0 + 1, len(frames) - 1)
    w = (t - i0)[..., None].astype(np.float32)
    out = (1.0 - w) * frames[i0] + w * frames[i1]
    out[..., -3:] *= speeds[:, :, None].astype(np.float32)
    return out.astype(np.float32)
