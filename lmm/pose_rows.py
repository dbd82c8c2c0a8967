"""One pose's rows of floats (lists of tuples, as the per-tick code keeps them) packed into numpy arrays."""
from __future__ import annotations

import itertools
import struct

import numpy as np

_PACKERS: dict = {}


def pack_rows(blocks, n: int, dtype) -> tuple:
    """New (n, width) arrays of ``dtype`` (float32 or float64), one per ``(rows, width)`` of ``blocks``
    (``rows``: ``n`` tuples of ``width`` floats), as views of one new buffer: every float packed straight
    into its memory by one :mod:`struct` call (about half the time of ``np.fromiter`` over the chained
    tuples, and one call for a whole pose's arrays). Each float is rounded to float32 as a C cast does, as
    numpy's cast does (the same bits, ``tests/lmm/test_pose_rows.py``); with another dtype, or a Python whose
    packing refuses an out-of-range float, numpy converts."""
    dtype = np.dtype(dtype)
    widths = tuple(w for _, w in blocks)
    total = n * sum(widths)
    every = []
    for r, _ in blocks:
        every += r
    flat = None
    if dtype.char in "fd":
        key = (total, dtype.char)
        packer = _PACKERS.get(key)
        if packer is None:
            packer = _PACKERS[key] = struct.Struct(f"={total}{dtype.char}")
        flat = np.empty(total, dtype)
        try:
            packer.pack_into(flat, 0, *itertools.chain.from_iterable(every))
        except (OverflowError, struct.error):
            flat = None
    if flat is None:
        flat = np.fromiter(itertools.chain.from_iterable(every), dtype, total)
    out, start = [], 0
    for w in widths:
        out.append(flat[start:start + n * w].reshape(n, w))
        start += n * w
    return tuple(out)
