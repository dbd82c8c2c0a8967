"""Small signal filters on arrays over time (axis 0): Savitzky-Golay smoothing, median filter, resampling.

Written in numpy so the engine needs no scipy at run time.
"""
from __future__ import annotations

import numpy as np


def savgol_coefficients(window: int, order: int) -> np.ndarray:
    """Weights of the centred least-squares polynomial fit evaluated at the window centre."""
    if window % 2 == 0 or window < 1:
        raise ValueError(f"Savitzky-Golay window must be odd and positive, got {window}")
    if order >= window:
        raise ValueError(f"Savitzky-Golay order {order} must be less than the window {window}")
    half = window // 2
    x = np.arange(-half, half + 1, dtype=np.float64)
    vander = x[:, None] ** np.arange(order + 1)[None, :]
    # row 0 of the pseudo-inverse gives the constant term of the fit
    return np.linalg.pinv(vander)[0]


def savgol_smooth(x: np.ndarray, window: int, order: int) -> np.ndarray:
    """Smooth along axis 0 with edge values repeated past both ends.

    The window shrinks to the largest odd size that fits short signals.
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    window = min(window, n if n % 2 == 1 else n - 1)
    if window <= order or window < 3:
        return x.copy()
    coeffs = savgol_coefficients(window, order)
    half = window // 2
    padded = np.concatenate([np.repeat(x[:1], half, axis=0), x, np.repeat(x[-1:], half, axis=0)], axis=0)
    out = np.zeros_like(x)
    for k, c in enumerate(coeffs):
        out += c * padded[k:k + n]
    return out


def median_filter(x: np.ndarray, window: int) -> np.ndarray:
    """Centred running median along axis 0 (odd window; edges repeat the end values)."""
    x = np.asarray(x, dtype=np.float64)
    if window <= 1:
        return x.copy()
    if window % 2 == 0:
        raise ValueError(f"median window must be odd, got {window}")
    half = window // 2
    n = x.shape[0]
    padded = np.concatenate([np.repeat(x[:1], half, axis=0), x, np.repeat(x[-1:], half, axis=0)], axis=0)
    stacked = np.stack([padded[k:k + n] for k in range(window)], axis=0)
    return np.median(stacked, axis=0)


#: output rows per block of :func:`catmull_rom` (each block's temporaries stay in cache)
CATMULL_ROM_BLOCK = 1024


def catmull_rom(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Cubic (Catmull-Rom) interpolation of samples x[0..n-1] (axis 0) at fractional indices t.

    Each output row depends only on its own ``t`` and four samples, so long outputs are made a block of
    rows at a time (the same operations on the same values: the same bits, and several times less
    memory traffic than whole-take temporaries)."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    t = np.clip(np.asarray(t, dtype=np.float64), 0, n - 1)
    if t.ndim != 1:
        return _catmull_rom_rows(x, t, n)
    out = np.empty(t.shape + x.shape[1:])
    for start in range(0, len(t), CATMULL_ROM_BLOCK):
        s = slice(start, start + CATMULL_ROM_BLOCK)
        out[s] = _catmull_rom_rows(x, t[s], n)
    return out


def _catmull_rom_rows(x: np.ndarray, t: np.ndarray, n: int) -> np.ndarray:
    i1 = np.floor(t).astype(np.int64)
    i1 = np.minimum(i1, n - 1)
    i2 = np.minimum(i1 + 1, n - 1)
    i0 = np.maximum(i1 - 1, 0)
    i3 = np.minimum(i1 + 2, n - 1)
    u = (t - i1).reshape((-1,) + (1,) * (x.ndim - 1))
    p0, p1, p2, p3 = x[i0], x[i1], x[i2], x[i3]
    return 0.5 * ((2 * p1) + (-p0 + p2) * u + (2 * p0 - 5 * p1 + 4 * p2 - p3) * u ** 2
                  + (-p0 + 3 * p1 - 3 * p2 + p3) * u ** 3)


def central_difference(x: np.ndarray, dt: float) -> np.ndarray:
    """Time derivative along axis 0: central differences inside, one-sided at the two ends."""
    x = np.asarray(x, dtype=np.float64)
    if x.shape[0] < 2:
        return np.zeros_like(x)
    return np.gradient(x, dt, axis=0)
