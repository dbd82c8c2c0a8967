"""Per-database arrays derived from every frame (features, root velocities, contact heights...), cached
beside the database file so a run does not read every frame again.

A pass over all frames of a memory-mapped database touches all of its pages, which then count as the
run's resident memory (0.6 GB for the 0.5 M-frame LAFAN1 set) and costs seconds. :func:`cached` computes
such an array once, stores it as a plain ``.npy`` in ``<database file>.derived/`` and afterwards
memory-maps it. An entry's name carries a hash of the database key, the database build code, the
parameters and the source of the module that computes it, so a change to any of them computes it again
(older entries of the same name are removed). Databases that were not loaded from a file (built in
memory, tests) compute every time, exactly as before: a cached array is bit-identical to a computed one.

An entry is never trusted: its CRC-32 is stored beside it (``.crc32``) when it is written and checked
when it is opened, so a bit flip, a NaN written into it, a truncated or 0-byte file is computed and
written again with a one-line note on stderr, never used (a damaged entry once gave a different
recording with exit 0, or stopped every command, ``build-db --rebuild`` included, with ``EOFError``).
Its shape, type and values are checked against the database too, so one whose checksum was written to
match is not used either (:func:`misfit`).
"""
from __future__ import annotations

import hashlib
import inspect
import json
import sys
import zlib
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


def checksum_path(path: Path) -> Path:
    """Where the CRC-32 of the entry ``path`` is kept."""
    return path.with_name(path.name + ".crc32")


def file_crc32(path) -> str:
    """CRC-32 of a file's bytes (8 hex digits), read in 1 MB pieces (through the page cache, not mapped)."""
    crc = 0
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            crc = zlib.crc32(chunk, crc)
    return f"{crc:08x}"


def damage(path: Path) -> str | None:
    """Why the entry ``path`` cannot be trusted (None: its bytes are the ones written). An entry without
    its checksum (written by older code, or cut off before the checksum) is not trusted either."""
    try:
        recorded = checksum_path(path).read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError):
        return "no checksum"
    try:
        if path.stat().st_size == 0:
            return "an empty file"
        found = file_crc32(path)
    except OSError as e:
        return f"unreadable ({e.strerror})"
    return None if found == recorded else f"its CRC-32 {found} is not the {recorded[:8]} written with it"


def _frames(db) -> int | None:
    n = getattr(db, "n_frames", None)
    return int(n) if isinstance(n, (int, np.integer)) else None


def _ranges(db) -> int | None:
    starts = getattr(db, "range_starts", None)
    return None if starts is None else int(len(starts))


#: what each kind of entry must be for ``db``: (shape, None where any length; dtype kind; value rule).
#: A checksum written to match does not make an entry right (a hand-made one gave exit 70 or another
#: recording), so a trusted entry's shape, type and values are checked too
_KINDS = {
    "features": (lambda db: (_frames(db), None), "f", "finite"),
    "root_local_velocities": (lambda db: (_frames(db), 6), "f", "finite"),
    "compressor_latents": (lambda db: (_frames(db), None), "f", "finite"),
    "range_contact_heights": (lambda db: (_ranges(db),), "f", "not_inf"),   # NaN: a range without contact
    "default_start_frame": (lambda db: (), "i", "frame"),
    "source_ground_skating": (lambda db: (2,), "i", "counts"),
}


def _finite_on_disk(path: Path, array: np.ndarray, chunk: int = 1 << 20) -> bool:
    """Whether every value of the ``.npy`` file ``path`` (whose array is ``array``) is finite, read in
    pieces through the page cache like its checksum: a random-access entry's map keeps its pages out."""
    with open(path, "rb") as f:
        f.seek(path.stat().st_size - array.nbytes)   # an .npy file ends with its data
        while True:
            part = np.fromfile(f, dtype=array.dtype, count=max(chunk // array.dtype.itemsize, 1))
            if part.size == 0:
                return True
            if not np.isfinite(part).all():
                return False


def misfit(db, name: str, array: np.ndarray, on_disk: Path | None = None) -> str | None:
    """Why a cached ``name`` array cannot be ``db``'s (None: it can): its shape, its type and its values
    (read from the file ``on_disk`` when given, so a random-access map stays cold)."""
    kind = _KINDS.get(name)
    if kind is None:
        return None
    shape_of, dtype_kind, rule = kind
    want = shape_of(db)
    if array.ndim != len(want) or any(w is not None and w != n for w, n in zip(want, array.shape)):
        return f"shape {array.shape}, expected {tuple('any' if w is None else w for w in want)}"
    if array.dtype.kind != dtype_kind:
        return f"type {array.dtype}"
    if rule == "finite" and not (_finite_on_disk(on_disk, array) if on_disk is not None
                                 else np.isfinite(array).all()):
        return "values that are not finite"
    if rule == "not_inf" and np.isinf(array).any():
        return "infinite values"
    n = _frames(db)
    if rule == "frame" and not (0 <= int(array) < (n if n is not None else np.iinfo(np.int64).max)):
        return f"frame {int(array)} outside the database"
    if rule == "counts" and not (0 <= int(array[0]) <= int(array[1])):
        return f"counts {array.tolist()} that cannot be"
    return None


def cached(db, name: str, params, compute: Callable[[], np.ndarray], random_access: bool = False) -> np.ndarray:
    """``compute()``'s array for ``db``, from the cache beside its file when there (read-only memory map),
    else computed and stored. A cache that cannot be read or written is ignored (the array is computed).
    ``random_access``: the caller reads a few rows here and there (see :mod:`lmm.data.npz_mmap`)."""
    path = entry_path(db, name, params, compute)
    if path is not None and path.is_file():
        why = damage(path)
        if why is None:
            try:
                # mapped when the database is (a large one), else read whole: see npz_mmap.worth_mapping
                array = _map(path, random_access, mapped=worth_mapping(getattr(db, "source_path", None) or path))
                why = misfit(db, name, array, on_disk=path if random_access else None)
                if why is None:
                    return array
            except Exception as e:  # noqa: BLE001 - whatever np.load makes of it (EOFError...): computed again
                why = f"cannot be read ({type(e).__name__})"
        if why != "no checksum":
            print(f"note: {path}: damaged cached array ({why}); computing it again", file=sys.stderr)
    value = np.asarray(compute())
    if path is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_write(path) as f:
                np.save(f, value, allow_pickle=False)
            with atomic_write(checksum_path(path), "w") as f:   # after the entry: no checksum, no trust
                f.write(file_crc32(path) + "\n")
            for old in path.parent.glob(f"{name}-*.npy"):  # entries of older code or settings
                if old != path:
                    old.unlink(missing_ok=True)
                    checksum_path(old).unlink(missing_ok=True)
        except OSError:
            pass
    return value
