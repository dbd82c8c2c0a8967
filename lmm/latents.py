"""The compressor's latent of database frames, numpy only (run time and offline).

The compressor (trained with the other networks, shipped as ``compressor.npz`` beside the runtime
weights) maps a database frame's pose to the latent the decompressor needs beside the features. The
runtime never runs it per tick: :func:`database_latents` computes the latent of every frame once, and
the motion matching controller looks up the latent of the frame it plays (``DebugSnapshot.matched_latent``)
so the studio can show MM's and LMM's latents side by side. Evaluation uses the same table.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from lmm.data.derived import cached, file_digest, module_source_digest
from lmm.data.weights import WeightsError, layout_signature, load as load_weights
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


def cached_database_latents(path, db, features=None) -> np.ndarray:
    """:func:`database_latents` of every frame for the compressor in the weights file ``path``, float32
    (N, L), kept beside the database file like its other derived arrays (:func:`lmm.data.derived.cached`):
    computed once per compressor file, database, feature layout and code, then read, instead of on every
    studio start (5.6 s for the shipped 57,500 frames on a 2-core machine, in a thread that slows the GUI
    meanwhile). The same bits as computing it. The file is checked as :func:`load_compressor` checks it
    when the table is computed; a stored table was made from the same file bytes, database and layout."""
    path = Path(path)
    try:
        digest = file_digest(path)
    except OSError as e:
        raise WeightsError(f"{path}: cannot read the compressor: {e.strerror or type(e).__name__}") from None
    layout = None if features is None else layout_signature(features.layout_dicts())   # weights only rescale
    params = [digest, layout, module_source_digest(pose_vectors)]
    return cached(db, "compressor_latents", params,
                  lambda: database_latents(load_compressor(path, db, features), db).astype(np.float32),
                  random_access=True)


def database_latents(compressor: MLP, db, frames=None) -> np.ndarray:
    """The compressor's latent of every database frame (or of ``frames``, an index array), (N, L) float32."""
    if frames is None:
        c_in = np.concatenate([pose_vectors(db), character_space(db)], axis=1)
        return batched(compressor, c_in)
    frames = np.asarray(frames, dtype=np.int64)
    return batched(lambda f: compressor(np.concatenate([pose_vectors(db, f), character_space(db, f)], axis=1)),
                   frames, chunk=1024) if len(frames) else np.zeros((0, compressor.n_out), np.float32)
