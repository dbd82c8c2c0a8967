"""Learned embeddings of pose windows, run in numpy: the contrastive encoder and the classifier baseline.

Both are the same kind of network (:class:`ConvNet`), trained in :mod:`lmm.offline.search_training`:
per-feature normalisation, 1D convolutions over time (the window's ``FRAME_DIM`` features are the
channels), each followed by ReLU, then the mean and the max over time concatenated, then fully connected
layers (ReLU between them, none after the last). The embedding is the output of the first
``embed_fc`` fully connected layers (after its ReLU unless it is the last layer), optionally L2-normalised:

* ``encoder``: every layer, 64-D, L2-normalised (trained contrastively);
* ``classifier``: the inner 512-D layer of an action classifier (the approach this project grew from).

File format (pickle-free ``.npz``): arrays ``in_mean``, ``in_std`` ``(FRAME_DIM,)``, ``conv{i}.weight``
``(out, in, kernel)``, ``conv{i}.bias``, ``fc{i}.weight`` ``(out, in)``, ``fc{i}.bias`` (float32, torch's
layouts); ``metadata``: UTF-8 JSON as uint8 with ``format_version``, ``kind``, ``name``, ``window_frames``,
``frame_dim``, ``convs`` (``[out, kernel, stride]`` each), ``fcs`` (output sizes), ``embed_fc``,
``l2_normalize``, optional ``labels`` and ``training``. :func:`load` checks all of it and raises
:class:`SearchWeightsError` naming the file and the field or array.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from lmm.data import archive
from lmm.data.archive import METADATA
from lmm.errors import InputError
from lmm.motion_search.windows import FRAME_DIM, WINDOW_FRAMES

FORMAT_VERSION = 1
KINDS = ("encoder", "classifier")
DEFAULT_WEIGHTS = Path(__file__).resolve().parents[1] / "data" / "weights" / "search_encoder.npz"
CLASSIFIER_WEIGHTS = DEFAULT_WEIGHTS.with_name("search_classifier.npz")
MAX_UNITS = 2048            # widest layer (the shipped ones: 128 channels, 512 units)
MAX_LAYERS = 8              # convolutions, and fully connected layers
MAX_KERNEL = 15
MAX_MAGNITUDE = 1e4         # any weight, bias or normalisation entry (trained ones stay under ~10)
MAX_METADATA_BYTES = 256 * 1024


class SearchWeightsError(InputError):
    """A search network file that cannot be used; the message names the file and the problem."""


class ConvNet:
    """A window embedder (see the module doc); implements :class:`lmm.motion_search.embed.Embedder`."""

    def __init__(self, arrays: dict[str, np.ndarray], metadata: dict, digest: str = ""):
        self.arrays = {k: np.asarray(v, np.float32) for k, v in arrays.items()}
        self.metadata = metadata
        self.kind = metadata["kind"]
        self.convs = [tuple(int(v) for v in c) for c in metadata["convs"]]
        self.fcs = [int(v) for v in metadata["fcs"]]
        self.embed_fc = int(metadata["embed_fc"])
        self.l2_normalize = bool(metadata["l2_normalize"])
        self.labels = list(metadata.get("labels", []))
        # the name says which weights made the vectors (i13-find's index cache is keyed by it)
        self.name = f"{metadata.get('name', self.kind)}-{digest[:12]}" if digest else metadata.get("name", self.kind)

    @property
    def dim(self) -> int:
        return self.fcs[self.embed_fc - 1]

    def _trunk(self, windows: np.ndarray) -> np.ndarray:
        a = self.arrays
        x = (np.asarray(windows, np.float32) - a["in_mean"]) / a["in_std"]   # (n, T, C)
        for i, (_, kernel, stride) in enumerate(self.convs):
            x = relu(conv1d_time(x, a[f"conv{i}.weight"], a[f"conv{i}.bias"], stride))
        return np.concatenate([x.mean(axis=1), x.max(axis=1)], axis=1)

    def _head(self, h: np.ndarray, n_layers: int) -> np.ndarray:
        for i in range(n_layers):
            h = h @ self.arrays[f"fc{i}.weight"].T + self.arrays[f"fc{i}.bias"]
            if i < len(self.fcs) - 1:
                h = relu(h)
        return h

    def embed(self, windows: np.ndarray, chunk: int = 4096) -> np.ndarray:
        """``(n, WINDOW_FRAMES, FRAME_DIM)`` -> ``(n, dim)`` float32 (in chunks of ``chunk`` windows)."""
        windows = np.asarray(windows, np.float32)
        out = np.empty((len(windows), self.dim), np.float32)
        for s in range(0, len(windows), chunk):
            h = self._head(self._trunk(windows[s:s + chunk]), self.embed_fc)
            if self.l2_normalize:
                h = h / np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-12)
            out[s:s + chunk] = h
        return out

    def logits(self, windows: np.ndarray) -> np.ndarray:
        """Every layer (the classifier's class scores, in ``labels`` order)."""
        return self._head(self._trunk(windows), len(self.fcs))


def relu(x: np.ndarray) -> np.ndarray:
    return np.maximum(x, 0.0, out=x)


def conv1d_time(x: np.ndarray, weight: np.ndarray, bias: np.ndarray, stride: int) -> np.ndarray:
    """``(n, T, C_in)`` -> ``(n, T_out, C_out)``: torch's ``Conv1d(C_in, C_out, k, stride, padding=k // 2)``
    (zero padding), as one matrix product over the unfolded windows."""
    n, T, C = x.shape
    out_c, in_c, k = weight.shape
    pad = k // 2
    xp = np.zeros((n, T + 2 * pad, C), np.float32)
    xp[:, pad:pad + T] = x
    cols = np.lib.stride_tricks.sliding_window_view(xp, k, axis=1)[:, ::stride]  # (n, T_out, C, k)
    t_out = cols.shape[1]
    y = cols.reshape(n * t_out, C * k) @ weight.reshape(out_c, in_c * k).T
    return (y + bias).reshape(n, t_out, out_c).astype(np.float32, copy=False)


def expected_shapes(meta: dict) -> dict[str, tuple[int, ...]]:
    shapes = {"in_mean": (FRAME_DIM,), "in_std": (FRAME_DIM,)}
    c = FRAME_DIM
    for i, (out, kernel, _) in enumerate(meta["convs"]):
        shapes[f"conv{i}.weight"] = (out, c, kernel)
        shapes[f"conv{i}.bias"] = (out,)
        c = out
    f = 2 * c
    for i, out in enumerate(meta["fcs"]):
        shapes[f"fc{i}.weight"] = (out, f)
        shapes[f"fc{i}.bias"] = (out,)
        f = out
    return shapes


def _fail(path, msg):
    raise SearchWeightsError(f"{path}: {msg}")


def _is_int(v, lo, hi) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi


def check_metadata(path, meta) -> None:
    """Every metadata field the loader reads, present and in range (SearchWeightsError naming it)."""
    if not isinstance(meta, dict):
        _fail(path, "metadata record is not a JSON object")
    if meta.get("format_version") != FORMAT_VERSION:
        _fail(path, f"search network format {repr(meta.get('format_version'))[:40]}, expected {FORMAT_VERSION}")
    if meta.get("kind") not in KINDS:
        _fail(path, f"metadata field 'kind': expected one of {', '.join(KINDS)}, got {repr(meta.get('kind'))[:40]}")
    for key, want in (("window_frames", WINDOW_FRAMES), ("frame_dim", FRAME_DIM)):
        if meta.get(key) != want:
            _fail(path, f"metadata field {key!r} is {repr(meta.get(key))[:40]}, this program's windows have {want} "
                        f"(trained on another window representation)")
    convs = meta.get("convs")
    if not isinstance(convs, list) or not 1 <= len(convs) <= MAX_LAYERS or not all(
            isinstance(c, list) and len(c) == 3 and _is_int(c[0], 1, MAX_UNITS) and _is_int(c[1], 1, MAX_KERNEL)
            and c[1] % 2 == 1 and _is_int(c[2], 1, 4) for c in convs):
        _fail(path, f"metadata field 'convs': expected 1..{MAX_LAYERS} [out <= {MAX_UNITS}, odd kernel <= "
                    f"{MAX_KERNEL}, stride 1..4] triples, got {repr(convs)[:60]}")
    fcs = meta.get("fcs")
    if not isinstance(fcs, list) or not 1 <= len(fcs) <= MAX_LAYERS or not all(_is_int(v, 1, MAX_UNITS) for v in fcs):
        _fail(path, f"metadata field 'fcs': expected 1..{MAX_LAYERS} layer sizes in [1, {MAX_UNITS}], "
                    f"got {repr(fcs)[:60]}")
    if not _is_int(meta.get("embed_fc"), 1, len(fcs)):
        _fail(path, f"metadata field 'embed_fc': expected an integer in [1, {len(fcs)}], "
                    f"got {repr(meta.get('embed_fc'))[:40]}")
    if not isinstance(meta.get("l2_normalize"), bool):
        _fail(path, "metadata field 'l2_normalize': expected true or false")
    labels = meta.get("labels", [])
    if not isinstance(labels, list) or not all(isinstance(s, str) for s in labels):
        _fail(path, "metadata field 'labels': expected a list of strings")
    if meta["kind"] == "classifier" and len(labels) != fcs[-1]:
        _fail(path, f"metadata field 'labels' has {len(labels)} entries, the classifier's last layer {fcs[-1]}")


def load(path) -> ConvNet:
    """Load and validate a search network file (see the module doc for what is refused)."""
    path = Path(path)
    if not path.is_file():
        from lmm.data.reading import not_regular

        _fail(path, not_regular(path, "search network file"))
    with archive.read(path, SearchWeightsError, "search network file") as r:
        if METADATA not in r:
            _fail(path, "not a search network file (no metadata record)")
        meta = r.metadata(MAX_METADATA_BYTES)
        check_metadata(path, meta)
        shapes = expected_shapes(meta)
        r.refuse_unknown(shapes)
        arrays = r.float_arrays(shapes, MAX_MAGNITUDE)
        digest = hashlib.sha256(path.read_bytes()).hexdigest()   # names the embedder in index caches
    if np.any(arrays["in_std"] <= 0):
        _fail(path, "in_std has non-positive entries (a normalisation scale must be positive)")
    return ConvNet(arrays, meta, digest)


def save(path, arrays: dict[str, np.ndarray], metadata: dict) -> Path:
    """Write a network file (an archive, :mod:`lmm.data.archive`); refuses arrays that do not match the
    metadata."""
    meta = dict(metadata, format_version=FORMAT_VERSION, window_frames=WINDOW_FRAMES, frame_dim=FRAME_DIM)
    check_metadata(path, meta)
    shapes = expected_shapes(meta)
    for key, shape in shapes.items():
        if key not in arrays or tuple(np.shape(arrays[key])) != shape:
            _fail(path, f"refusing to save: {key} is missing or not {shape}")
    return archive.write(path, {k: np.ascontiguousarray(arrays[k], dtype=np.float32) for k in shapes}, meta)


def load_default() -> ConvNet | None:
    """The shipped encoder (``lmm/data/weights/search_encoder.npz``), or None when it is not there."""
    return load(DEFAULT_WEIGHTS) if DEFAULT_WEIGHTS.is_file() else None
