"""Memory-map the arrays of an uncompressed ``.npz`` (what ``np.savez`` writes) without reading them.

``np.load(..., mmap_mode="r")`` maps plain ``.npy`` files only; for an ``.npz`` it reads every member
into memory. An uncompressed zip member is, however, an ``.npy`` file stored byte for byte at a known
offset of the archive, so it can be mapped in place: the operating system then reads a page only when
it is first touched, and a run that plays a few thousand frames of a 0.5 M-frame database keeps only
those pages resident. The archive stays an ordinary ``.npz`` (``np.load`` still reads it).
"""
from __future__ import annotations

import mmap
import os
import struct
import zipfile
from pathlib import Path

import numpy as np

#: Files smaller than this are read into memory instead of mapped (see :func:`worth_mapping`).
MAP_MIN_BYTES = 256 << 20

_LOCAL_HEADER = struct.Struct("<4s2B4HL2L2H")  # the zip local file header (30 bytes)
_LOCAL_SIGNATURE = b"PK\x03\x04"


def _member_data_offset(f, info: zipfile.ZipInfo) -> int:
    """Where a member's stored bytes start: after its local header, name and extra field."""
    f.seek(info.header_offset)
    header = f.read(_LOCAL_HEADER.size)
    if len(header) != _LOCAL_HEADER.size or header[:4] != _LOCAL_SIGNATURE:
        raise ValueError(f"bad local header for {info.filename}")
    fields = _LOCAL_HEADER.unpack(header)
    name_len, extra_len = fields[-2], fields[-1]
    return info.header_offset + _LOCAL_HEADER.size + name_len + extra_len


def worth_mapping(path) -> bool:
    """Map a cache file only when it is large (at least :data:`MAP_MIN_BYTES`, e.g. the 577 MB cache of
    the full LAFAN1 set). A small one (the default data's 70 MB) is read whole: mapped with its cached
    pages dropped, each frame a run visits for the first time would be a disk read of 1-8 ms inside a
    tick (measured: 889 major faults in 32 s of motion matching), and its memory is no concern."""
    try:
        return os.path.getsize(path) >= MAP_MIN_BYTES
    except OSError:
        return False


def drop_cached_pages(fileno: int) -> None:
    """Ask the kernel to forget the file's clean cached pages (pages other processes map are kept).

    A file just written, or read in bulk, sits in the page cache in large folios (up to megabytes);
    mapping it then makes one touched frame map its whole folio, so a run that visits a few thousand
    frames would count most of the file as resident. Dropped pages are read again, one page each under
    :func:`advise_random`, when touched."""
    if hasattr(os, "posix_fadvise"):
        try:
            os.posix_fadvise(fileno, 0, 0, os.POSIX_FADV_DONTNEED)
        except OSError:
            pass


def advise_random(array: np.memmap) -> None:
    """Tell the kernel the pages are read in no order: no read-ahead around a touched page (else each
    frame a run jumps to brings in 64-128 KB around it)."""
    mm = getattr(array, "_mmap", None)
    if mm is not None and hasattr(mm, "madvise") and hasattr(mmap, "MADV_RANDOM"):
        try:
            mm.madvise(mmap.MADV_RANDOM)
        except OSError:
            pass


def map_members(path, names, random_access: bool = True) -> dict[str, np.ndarray]:
    """Read-only ``np.memmap`` of each ``.npz`` member in ``names`` that is stored uncompressed and holds
    a plain (non-object) array; members that cannot be mapped are left out (the caller reads them).
    ``random_access`` (a run reads a few frames here and there) drops the file's cached pages and turns
    off the kernel's read-ahead for the maps, so memory holds about the pages that were touched."""
    path = Path(path)
    out: dict[str, np.ndarray] = {}
    with zipfile.ZipFile(path) as z, open(path, "rb") as f:
        if random_access:
            drop_cached_pages(f.fileno())
        for name in names:
            try:
                info = z.getinfo(name + ".npy")
            except KeyError:
                continue
            if info.compress_type != zipfile.ZIP_STORED:
                continue
            start = _member_data_offset(f, info)
            f.seek(start)
            version = np.lib.format.read_magic(f)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
            elif version == (2, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
            else:
                continue
            if dtype.hasobject:
                continue
            offset = f.tell()
            size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
            if offset + size > start + info.file_size or size == 0:
                continue  # an empty array cannot be mapped (and costs nothing to read)
            array = np.memmap(path, dtype=dtype, mode="r", offset=offset, shape=shape,
                              order="F" if fortran else "C")
            if random_access:
                advise_random(array)
            out[name] = array
    return out
