"""Dynamic time warping between a query and candidate segments of pose frames (the re-ranking step).

The cost of matching frame ``i`` of one sequence with frame ``j`` of the other is their squared Euclidean
distance; the DTW distance is the square root of the smallest total cost over warping paths from
``(0, 0)`` to ``(n-1, m-1)`` (steps right, down, diagonal), inside a **Sakoe-Chiba band** of half-width
``window``: row ``i`` may use columns ``[i - max(0, n-m) - window + 1, i + max(0, m-n) + window)``, the band
widened by the length difference so that sequences of different lengths always have a path. This is
dtaidistance's definition (``dtw_ndim.distance(s1, s2, window=window)``), so :func:`dtw_distances` may
use that library's C code when it is installed (the ``search`` extra) and gives the same numbers without.

:func:`dtw_distances` compares one query with a batch of equally long candidates in numpy, one
anti-diagonal at a time (cells on an anti-diagonal do not depend on each other), vectorised over the
batch and the diagonal: ``n + m`` numpy steps whatever the batch size.
"""
from __future__ import annotations

import functools

import numpy as np


def band_mask(n: int, m: int, window: int | None) -> np.ndarray:
    """``(n, m)`` bool: the cells inside the Sakoe-Chiba band (all cells when ``window`` is None)."""
    if window is None:
        return np.ones((n, m), bool)
    w = max(1, int(window))
    i = np.arange(n)[:, None]
    j = np.arange(m)[None, :]
    lo = i - max(0, n - m) - w + 1
    hi = i + max(0, m - n) + w
    return (j >= lo) & (j < hi)


def dtw_reference(a: np.ndarray, b: np.ndarray, window: int | None = None) -> float:
    """The plain double loop (for tests): DTW distance between ``(n, D)`` and ``(m, D)``."""
    n, m = len(a), len(b)
    inside = band_mask(n, m, window)
    acc = np.full((n + 1, m + 1), np.inf)
    acc[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            if inside[i - 1, j - 1]:
                cost = float(np.sum((np.asarray(a[i - 1], float) - np.asarray(b[j - 1], float)) ** 2))
                acc[i, j] = cost + min(acc[i - 1, j - 1], acc[i - 1, j], acc[i, j - 1])
    return float(np.sqrt(acc[n, m]))


def _dtw_numpy(query: np.ndarray, candidates: np.ndarray, window: int | None) -> np.ndarray:
    q = np.asarray(query, np.float64)
    c = np.asarray(candidates, np.float64)
    B, m = c.shape[0], c.shape[1]
    n = q.shape[0]
    cost = ((q[None, :, None, :] - c[:, None, :, :]) ** 2).sum(-1)          # (B, n, m)
    cost[:, ~band_mask(n, m, window)] = np.inf
    acc = np.full((B, n + 1, m + 1), np.inf)
    acc[:, 0, 0] = 0.0
    for k in range(2, n + m + 1):            # 1-based cell (i, j) with i + j = k
        i = np.arange(max(1, k - m), min(n, k - 1) + 1)
        j = k - i
        best = np.minimum(np.minimum(acc[:, i - 1, j - 1], acc[:, i - 1, j]), acc[:, i, j - 1])
        acc[:, i, j] = cost[:, i - 1, j - 1] + best
    return np.sqrt(acc[:, n, m])


def _dtw_dtaidistance(query: np.ndarray, candidates: np.ndarray, window: int | None) -> np.ndarray:
    from dtaidistance import dtw_ndim

    q = np.ascontiguousarray(query, np.float64)
    w = None if window is None else max(1, int(window))
    return np.array([dtw_ndim.distance_fast(q, np.ascontiguousarray(s, np.float64), window=w)
                     for s in candidates])


@functools.lru_cache(maxsize=1)
def have_dtaidistance() -> bool:
    """dtaidistance and its compiled C part import (checked once; its own check prints to stdout)."""
    try:
        from dtaidistance import dtw_cc  # noqa: F401

        return True
    except Exception:  # noqa: BLE001 - absent or a broken build: the numpy path serves
        return False


def dtw_distances(query: np.ndarray, candidates: np.ndarray, window: int | None = None,
                  backend: str = "auto") -> np.ndarray:
    """DTW distance between ``query`` ``(n, D)`` and each of ``candidates`` ``(B, m, D)``: ``(B,)``.

    ``backend``: ``"numpy"``, ``"dtaidistance"`` (its C code; ImportError when absent) or ``"auto"``
    (dtaidistance when it is installed, which bench/find_latency.py measures as faster, else numpy)."""
    candidates = np.asarray(candidates)
    if candidates.ndim != 3 or len(candidates) == 0:
        return np.zeros(0)
    if backend == "auto":
        backend = "dtaidistance" if have_dtaidistance() else "numpy"
    if backend == "dtaidistance":
        return _dtw_dtaidistance(query, candidates, window)
    if backend != "numpy":
        raise ValueError(f"unknown DTW backend {backend!r} (numpy, dtaidistance, auto)")
    return _dtw_numpy(query, candidates, window)
