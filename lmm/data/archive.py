"""Archives of arrays + JSON metadata: the one file format of databases, network weights, search
networks and search caches.

An archive is an uncompressed, pickle-free ``.npz``: one ``.npy`` member per array and one member
``metadata`` holding UTF-8 JSON as a uint8 array (keys sorted by default, so the same content is the same
bytes: the search index names its cache after an encoder file's hash). Uncompressed, so a database's per-frame
arrays can be memory-mapped where they lie (:mod:`lmm.data.npz_mmap`). Written whole or not at all
(:func:`lmm.data.atomic.atomic_write`).

Reading (:func:`read`) costs what the caller allows before any work: a member's declared size is checked
against its limit before it is read, members the caller does not know are refused by their names in the
zip directory (never read: one might be huge or a pickled object), and the metadata record has a size
and a nesting limit. Every refusal is one line that names the file and the member or field, raised as
the caller's own error class.
"""
from __future__ import annotations

import json
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from lmm.data.atomic import atomic_write
from lmm.errors import InputError

#: The member that holds the JSON metadata.
METADATA = "metadata"
#: Default largest metadata record (bytes): a weights file's is ~5 KB, a 0.5 M-frame database's ~100 KB.
MAX_METADATA_BYTES = 1024 * 1024
#: A ``.npy`` member is its header (at most a few hundred bytes) plus the raw data.
NPY_HEADER_SLACK = 4096


class ArchiveError(InputError):
    """An archive that cannot be read; the message names the file and the member or field."""


def encode_metadata(metadata, sort_keys: bool = True) -> np.ndarray:
    """The metadata record: UTF-8 JSON bytes as a uint8 array."""
    return np.frombuffer(json.dumps(metadata, sort_keys=sort_keys).encode("utf-8"), dtype=np.uint8)


def write(path, arrays: dict[str, np.ndarray], metadata, sort_keys: bool = True) -> Path:
    """Write ``arrays`` and ``metadata`` to ``path`` atomically (a killed writer never leaves half a file).
    ``sort_keys`` False keeps the metadata's own order (a database's bone roles and feature schema read
    back in the manifest's order)."""
    if METADATA in arrays:
        raise ValueError(f"an archive array may not be named {METADATA!r}")
    path = Path(path)
    with atomic_write(path) as f:
        np.savez(f, **arrays, **{METADATA: encode_metadata(metadata, sort_keys)})
    return path


class Reader:
    """An open archive (see :func:`read`); each check raises the reader's error class naming the file."""

    def __init__(self, path: Path, z, error, mapped: dict | None = None):
        self.path, self._z, self.error = path, z, error
        self._mapped = mapped or {}
        self.files = list(z.files)

    def __contains__(self, name: str) -> bool:
        return name in self.files

    def fail(self, message: str):
        raise self.error(f"{self.path}: {message}")

    def declared_bytes(self, name: str) -> int:
        """The uncompressed size a member declares in the zip directory (what reading it would cost)."""
        return self._z.zip.getinfo(f"{name}.npy").file_size

    def check_size(self, name: str, limit: int, shape=None) -> None:
        """Refuse a member that declares more than ``limit`` bytes, before reading it."""
        size = self.declared_bytes(name)
        if size > limit:
            expected = f" for shape {shape}" if shape is not None else ""
            self.fail(f"member {name} declares {size} bytes, more than the {limit}{expected}")

    def refuse_unknown(self, known, holds: str = "") -> None:
        """Refuse any member not in ``known`` (``metadata`` is always known); ``holds`` says what the
        file should hold, for the message."""
        extra = sorted(f for f in self.files if f != METADATA and f not in known)
        if extra:
            self.fail(f"unexpected member {extra[0]!r} ({len(extra)} in all{'; ' + holds if holds else ''})")

    def metadata(self, max_bytes: int = MAX_METADATA_BYTES):
        """The parsed metadata record (any JSON value; the caller checks its fields)."""
        from lmm.data.jsonio import JsonError, parse_json

        if METADATA not in self.files:
            self.fail("no metadata record")
        self.check_size(METADATA, max_bytes)
        raw = self._z[METADATA]
        if raw.dtype != np.uint8 or raw.ndim != 1:
            self.fail(f"metadata record is not UTF-8 JSON bytes ({raw.dtype})")
        try:
            return parse_json(raw.tobytes().decode("utf-8"), self.path)
        except UnicodeDecodeError as e:
            self.fail(f"metadata record is not valid JSON (not UTF-8 at byte {e.start})")
        except JsonError as e:
            rest = str(e)[len(str(self.path)) + 2:]  # after "PATH: "
            self.fail(f"metadata record {'is ' if rest.startswith('not') else ''}{rest}")

    def array(self, name: str, shape=None) -> np.ndarray:
        """A member's array (its memory map when it was mapped). With ``shape`` the member may declare
        no more bytes than that shape in float64, so an oversized member is never read."""
        if name not in self.files:
            self.fail(f"missing array {name}")
        if shape is not None:
            self.check_size(name, int(np.prod(shape)) * 8 + NPY_HEADER_SLACK, shape)
        return self._mapped[name] if name in self._mapped else self._z[name]

    __getitem__ = array

    def float_arrays(self, shapes: dict[str, tuple], max_magnitude: float) -> dict[str, np.ndarray]:
        """The float arrays of ``shapes``, each checked: present, declared size, shape, float dtype, finite,
        ``|value| <= max_magnitude`` (trained networks stay far below it; beyond it float32 overflows)."""
        arrays = {key: self.array(key, shape) for key, shape in shapes.items()}
        for key, shape in shapes.items():
            a = arrays[key]
            if tuple(a.shape) != tuple(shape):
                self.fail(f"{key} has shape {tuple(a.shape)}, expected {tuple(shape)} (from the metadata)")
            if a.dtype.kind != "f":
                self.fail(f"{key} has dtype {a.dtype}, expected float32")
            if not np.all(np.isfinite(a)):
                self.fail(f"{key} holds {int(np.size(a) - np.count_nonzero(np.isfinite(a)))} NaN/inf values")
            if a.size and float(np.max(np.abs(a))) > max_magnitude:
                self.fail(f"{key} holds values up to {float(np.max(np.abs(a))):.3g}, beyond +-{max_magnitude:g}")
        return arrays


@contextmanager
def read(path, error=ArchiveError, what: str = "archive", map_arrays=()):
    """``with read(path, MyError, "weights file") as r: ...``: the archive at ``path`` opened for checked
    reading. Any failure to read it (not a zip, truncated, a damaged member) is ``error`` saying "truncated
    or corrupt ``what``". ``map_arrays``: members to memory-map instead of reading (uncompressed plain
    arrays only; the others are read as usual)."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            if not hasattr(z, "files"):
                raise error(f"{path}: not an lmm-studio {what} (a single array, not an .npz)")
            mapped = {}
            if map_arrays:
                from lmm.data.npz_mmap import map_members

                mapped = {k: np.asarray(v) for k, v in map_members(path, map_arrays).items()}
            yield Reader(path, z, error, mapped)
    except error:
        raise
    except Exception as e:  # zipfile.BadZipFile, EOFError, OSError, ValueError, zlib.error from a damaged member
        raise error(f"{path}: truncated or corrupt {what} ({type(e).__name__}: "
                    f"{' '.join(str(e).split())[:200]})") from None
