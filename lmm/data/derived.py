"""Per-database arrays derived from every frame (features, root velocities, contact heights...), cached
beside the database file so a run does not read every frame again.

A pass over all frames of a memory-mapped database touches all of its pages, which then count as the
run's resident memory (0.6 GB for the 0.5 M-frame LAFAN1 set) and costs seconds. :func:`cached` computes
such an array once, stores it as a plain ``.npy`` in ``<database file>.derived/`` and afterwards
memory-maps it. An entry's name carries a hash of the database key, the database build code, the
parameters and the source of the module that computes it, so a change to any of them computes it again
(older entries of the same name are removed). Databases that were not loaded from a file (built in
memory, tests) compute every time, exactly as before: a cached array is bit-identical to a computed one.
"""
from __future__ import annotations

import hashlib
import inspect
import json
from pathlib import Path
from typing import Callable

import numpy as np

from lmm.data.atomic import atomic_write
from lmm.data.npz_mmap import advise_random, drop_cached_pages, worth_mapping


def module_source_digest(fn) -> str:
    """SHA-256 of the source file of the module that defines ``fn`` ("unknown" when it has none)."""
    try:
        source = Path(inspect.getsourcefile(fn)).read_bytes()
    except (OSError, TypeError):
        return "unknown"
    return hashlib.sha256(source).hexdigest()


def file_digest(path) -> str:
    """SHA-256 of a file's bytes (hex), read in 1 MB pieces."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def derived_dir(db) -> Path | None:
    """The folder of ``db``'s derived arrays, or None for a database not loaded from a file."""
    source = getattr(db, "source_path", None)
    return None if source is None else derived_dir_of(source)


def derived_dir_of(database_file) -> Path:
    """The folder of the derived arrays of the database file ``database_file``."""
    return Path(str(database_file) + ".derived")


def entry_path(db, name: str, params, compute: Callable) -> Path | None:
    folder = derived_dir(db)
    if folder is None:
        return None
    h = hashlib.sha256()
    h.update(json.dumps([db.key, db.build_fingerprint, params], sort_keys=True, default=str).encode())
    h.update(module_source_digest(compute).encode())
    return folder / f"{name}-{h.hexdigest()[:20]}.npy"


def _map(path: Path, random_access: bool, mapped: bool = True) -> np.ndarray:
    if not mapped:  # beside a small database: read whole (read-only, like a map), no page faults in a tick
        array = np.load(path, allow_pickle=False)
        array.flags.writeable = False
        return array
    array = np.load(path, mmap_mode="r", allow_pickle=False)
    if random_access and isinstance(array, np.memmap):
        drop_cached_pages_of(path)
        advise_random(array)
    return np.asarray(array)


def drop_cached_pages_of(path: Path) -> None:
    with open(path, "rb") as f:
        drop_cached_pages(f.fileno())


def cached(db, name: str, params, compute: Callable[[], np.ndarray], random_access: bool = False) -> np.ndarray:
    """``compute()``'s array for ``db``, from the cache beside its file when there (read-only memory map),
    else computed and stored. A cache that cannot be read or written is ignored (the array is computed).
    ``random_access``: the caller reads a few rows here and there (see :mod:`lmm.data.npz_mmap`)."""
    path = entry_path(db, name, params, compute)
    if path is not None and path.is_file():
        try:
            # mapped when the database is (a large one), else read whole: see lmm.data.npz_mmap.worth_mapping
            return _map(path, random_access, mapped=worth_mapping(getattr(db, "source_path", None) or path))
        except (OSError, ValueError):
            pass  # damaged: computed and written again below
    value = np.asarray(compute())
    if path is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_write(path) as f:
                np.save(f, value, allow_pickle=False)
            for old in path.parent.glob(f"{name}-*.npy"):  # entries of older code or settings
                if old != path:
                    old.unlink(missing_ok=True)
        except OSError:
            pass
    return value
