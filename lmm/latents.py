"""The compressor's latent of database frames, numpy only (run time and offline).

The compressor (trained with the other networks, shipped as ``compressor.npz`` beside the runtime
weights) maps a database frame's pose to the latent the decompressor needs beside the features. The
runtime never runs it per tick: :func:`database_latents` computes the latent of every frame once, and
the motion matching controller looks up the latent of the frame it plays (``DebugSnapshot.matched_latent``)
so the studio can show MM's and LMM's latents side by side. Evaluation uses the same table.
"""
from __future__ import annotations

import numpy as np

from lmm.data.weights import load as load_weights
from lmm.nn import MLP, character_space, pose_vectors


def load_compressor(path, db=None, features=None) -> MLP:
    """The compressor network of a weights file, checked against ``db``'s key and ``features``' layout
    when given (raises :class:`lmm.data.weights.WeightsError` naming the file)."""
    wf = load_weights(path, require=["compressor"], db_key=None if db is None else db.key,
                      layout_dicts=None if features is None else features.layout_dicts())
    return MLP.from_spec(wf.arrays, "compressor", wf.spec("compressor"))


def batched(fn, x: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """``fn`` over the rows of ``x`` in chunks (bounded scratch memory), results concatenated."""
    return np.concatenate([fn(x[i:i + chunk]) for i in range(0, x.shape[0], chunk)])


def database_latents(compressor: MLP, db, frames=None) -> np.ndarray:
    """The compressor's latent of every database frame (or of ``frames``, an index array), (N, L) float32."""
    if frames is None:
        c_in = np.concatenate([pose_vectors(db), character_space(db)], axis=1)
        return batched(compressor, c_in)
    frames = np.asarray(frames, dtype=np.int64)
    return batched(lambda f: compressor(np.concatenate([pose_vectors(db, f), character_space(db, f)], axis=1)),
                   frames, chunk=1024) if len(frames) else np.zeros((0, compressor.n_out), np.float32)
