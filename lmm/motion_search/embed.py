"""Embeddings of pose windows and exact k-nearest-neighbour search over them.

An embedder turns windows ``(n, WINDOW_FRAMES, FRAME_DIM)`` (see :mod:`lmm.motion_search.windows`) into
vectors ``(n, dim)`` float32 compared by Euclidean distance. :class:`FeatureEmbedder` is the plain
baseline: the window's frames concatenated (every ``step`` th frame), each feature scaled by its spread
over a reference set so that no unit dominates. The learned encoder and the classifier baseline
implement the same two members (``name``, ``embed``).
"""
from __future__ import annotations

from typing import Protocol

import numpy as np

from lmm.motion_search.windows import FRAME_DIM, WINDOW_FRAMES


class Embedder(Protocol):
    name: str

    def embed(self, windows: np.ndarray) -> np.ndarray:
        """``(n, WINDOW_FRAMES, FRAME_DIM)`` -> ``(n, dim)`` float32."""


class FeatureEmbedder:
    """Concatenated key-joint features of every ``step`` th frame of the window, each divided by its
    standard deviation (``scale``, from :meth:`fit`; ones until fitted)."""

    name = "features"

    def __init__(self, step: int = 4, scale: np.ndarray | None = None):
        self.step = int(step)
        self.scale = np.ones(FRAME_DIM, np.float32) if scale is None else np.asarray(scale, np.float32)

    @property
    def dim(self) -> int:
        return len(range(0, WINDOW_FRAMES, self.step)) * FRAME_DIM

    def fit(self, frames: np.ndarray) -> "FeatureEmbedder":
        """Feature spreads over ``(n, FRAME_DIM)`` frames (a floor keeps a constant feature finite)."""
        std = np.asarray(frames, np.float64).reshape(-1, FRAME_DIM).std(axis=0)
        self.scale = np.maximum(std, 1e-3).astype(np.float32)
        return self

    def embed(self, windows: np.ndarray) -> np.ndarray:
        w = np.asarray(windows, np.float32)[:, :: self.step] / self.scale
        return np.ascontiguousarray(w.reshape(len(w), -1))


def knn(database: np.ndarray, queries: np.ndarray, k: int, chunk: int = 65536) -> tuple[np.ndarray, np.ndarray]:
    """Exact Euclidean k nearest neighbours: ``(indices, distances)``, each ``(q, k)``, nearest first.

    ``|q - d|^2 = |q|^2 - 2 q.d + |d|^2`` in float32 over database chunks of ``chunk`` rows (memory
    ``q x chunk`` floats), keeping the best ``k`` with argpartition."""
    db = np.ascontiguousarray(database, np.float32)
    q = np.ascontiguousarray(queries, np.float32).reshape(-1, db.shape[1] if db.ndim == 2 else queries.shape[-1])
    n = len(db)
    k = max(0, min(int(k), n))
    best_d = np.full((len(q), 0), np.inf, np.float32)
    best_i = np.zeros((len(q), 0), np.int64)
    if k == 0 or len(q) == 0:
        return best_i, best_d
    qn = np.einsum("ij,ij->i", q, q)[:, None]
    for start in range(0, n, chunk):
        part = db[start:start + chunk]
        d2 = qn - 2.0 * (q @ part.T) + np.einsum("ij,ij->i", part, part)[None, :]
        kk = min(k, part.shape[0])
        idx = np.argpartition(d2, kk - 1, axis=1)[:, :kk]
        best_d = np.concatenate([best_d, np.take_along_axis(d2, idx, axis=1)], axis=1)
        best_i = np.concatenate([best_i, idx + start], axis=1)
        if best_d.shape[1] > k:
            keep = np.argpartition(best_d, k - 1, axis=1)[:, :k]
            best_d = np.take_along_axis(best_d, keep, axis=1)
            best_i = np.take_along_axis(best_i, keep, axis=1)
    order = np.argsort(best_d, axis=1, kind="stable")
    best_d = np.sqrt(np.maximum(np.take_along_axis(best_d, order, axis=1), 0.0))
    return np.take_along_axis(best_i, order, axis=1), best_d
