"""Matching features: the layout is data, the database features are computed once, weights rescale.

The default layout is the paper's 27-D vector (section 3):

====== =========================================================================
dims   channel
====== =========================================================================
0-2    left foot position, root space          (weight 0.75)
3-5    right foot position, root space         (weight 0.75)
6-8    left foot velocity, root space          (weight 1.0)
9-11   right foot velocity, root space         (weight 1.0)
12-14  hip velocity, root space                (weight 1.0)
15-20  future root positions (x, z) at +20/+40/+60 frames, root space (weight 1.0)
21-26  future root facing (x, z) at +20/+40/+60 frames, root space    (weight 1.5)
====== =========================================================================

Each channel is one normalisation group: offset = per-dimension mean over the database,
scale = (mean of the channel's per-dimension standard deviations) / weight. Matching cost is the
squared Euclidean distance between normalised vectors. Changing a weight only rescales.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import numpy as np

from lmm import quat
from lmm.data.derived import cached
from lmm.data.feature_schema import DEFAULT_LAYOUT, Channel, layout_from_schema, schema_of
from lmm.filters import central_difference

FORWARD = np.array([0.0, 0.0, 1.0])  # the simulation bone faces +Z in its own space


def layout_slices(layout: Sequence[Channel]) -> list[slice]:
    out, start = [], 0
    for ch in layout:
        out.append(slice(start, start + ch.dims))
        start += ch.dims
    return out


def compute_raw(db, layout: Sequence[Channel] = DEFAULT_LAYOUT) -> np.ndarray:
    """Raw (unnormalised) features of every database frame, (N, D) float32, vectorised over frames."""
    # forward kinematics of the root and the feature bones only (not every bone of every frame)
    bones = sorted({0} | {db.bone(ch.bone) for ch in layout if ch.kind in ("bone_position", "bone_velocity")})
    column = {b: i for i, b in enumerate(bones)}
    g_rot, g_pos = db.global_transforms_of(bones)
    root_rot, root_pos = g_rot[:, column[0]], g_pos[:, column[0]]
    frames = np.arange(db.n_frames)
    # bone velocities: central differences of the global positions inside each range (one-sided at the
    # range ends), i.e. how fast the bone really moves through space, the quantity foot skating measures
    g_vel = np.empty_like(g_pos)
    for s, e in zip(db.range_starts, db.range_stops):
        g_vel[s:e] = central_difference(g_pos[s:e], db.dt)
    future = {off: db.future_frame(frames, off) for ch in layout
              if ch.kind in ("trajectory_position", "trajectory_direction") for off in ch.offsets}
    out = None
    # a few thousand frames at a time (the temporaries stay in the CPU cache); per frame the same maths
    for s in range(0, db.n_frames, _CHUNK_FRAMES):
        e = min(s + _CHUNK_FRAMES, db.n_frames)
        rr, rp = root_rot[s:e], root_pos[s:e]
        cols = []
        for ch in layout:
            if ch.kind == "bone_position":
                b = column[db.bone(ch.bone)]
                cols.append(quat.inv_mul_vec(rr, g_pos[s:e, b] - rp))
            elif ch.kind == "bone_velocity":
                b = column[db.bone(ch.bone)]
                cols.append(quat.inv_mul_vec(rr, g_vel[s:e, b]))
            elif ch.kind == "trajectory_position":
                for off in ch.offsets:
                    cols.append(quat.inv_mul_vec(rr, root_pos[future[off][s:e]] - rp)[:, [0, 2]])
            else:  # trajectory_direction
                for off in ch.offsets:
                    cols.append(quat.inv_mul_vec(rr, quat.mul_vec(root_rot[future[off][s:e]], FORWARD))[:, [0, 2]])
        chunk = np.concatenate(cols, axis=1)
        if out is None:
            out = np.empty((db.n_frames, chunk.shape[1]), dtype=np.float32)
        out[s:e] = chunk  # float64 -> float32 as astype does
    return out if out is not None else np.zeros((0, sum(ch.dims for ch in layout)), dtype=np.float32)


_CHUNK_FRAMES = 8192


def normalize_with(raw: np.ndarray, mean: np.ndarray, inv_scale: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``(raw - mean) * inv_scale`` as float32 (:meth:`Features.normalize` with a given scaling, e.g. one
    taken earlier), into ``out`` when given (float32 operands: the same float32 operations)."""
    out = np.subtract(raw, mean, out=out)
    out *= inv_scale  # in place: the same products as (raw - mean) * inv_scale, one array fewer
    return out if out.dtype == np.float32 else out.astype(np.float32)


@dataclass
class Features:
    """Database features plus their normalisation; ``normalized`` is what search compares against."""
    layout: list[Channel]
    raw: np.ndarray              # (N, D) float32
    mean: np.ndarray             # (D,) float32
    channel_std: np.ndarray      # (C,) float32: mean per-dim std of each channel (weight-free)
    weights: np.ndarray = field(default=None)  # (C,) float32
    normalized: np.ndarray = field(default=None, repr=False)  # (N, D) float32
    inv_scale: np.ndarray = field(default=None, repr=False)   # (D,) float32 = weight / channel std

    def __post_init__(self):
        self.layout = list(self.layout)
        self.slices = layout_slices(self.layout)
        self.channel_of_dim = np.concatenate([np.full(ch.dims, i) for i, ch in enumerate(self.layout)])
        if self.weights is None:
            self.weights = np.array([ch.weight for ch in self.layout], dtype=np.float32)
        self._rescale()

    @property
    def n_dims(self) -> int:
        return int(self.raw.shape[1])

    @property
    def names(self) -> list[str]:
        return [ch.name for ch in self.layout]

    def channel_index(self, name: str) -> int:
        for i, ch in enumerate(self.layout):
            if ch.name == name:
                return i
        raise KeyError(f"no feature channel named {name!r} (channels: {', '.join(self.names)})")

    #: ``normalized`` lives in a buffer of a whole multiple of this many rows, the rows past the last frame
    #: copies of it: :class:`lmm.search.SearchIndex` reads its blocks from that buffer without copying the
    #: features (51 MB for the 0.5 M-frame LAFAN1 set)
    ROW_MULTIPLE = 64

    def _rescale(self) -> None:
        std = np.maximum(self.channel_std, 1e-8)
        self.inv_scale = (self.weights / std)[self.channel_of_dim].astype(np.float32)
        n, d = self.raw.shape
        buf = np.empty((max(-(-n // self.ROW_MULTIPLE), 1) * self.ROW_MULTIPLE, d), np.float32)
        out = buf[:n]
        if self.raw.dtype == np.float32 and self.mean.dtype == np.float32:
            normalize_with(self.raw, self.mean, self.inv_scale, out=out)
        else:
            out[...] = (self.raw - self.mean) * self.inv_scale
        if n:
            buf[n:] = out[-1]
        self.normalized = out

    def set_weights(self, weights) -> bool:
        """Set channel weights (sequence in layout order, or {name: weight}); rescales, no raw recompute.

        Returns True when anything changed.
        """
        new = self.weights.copy()
        if isinstance(weights, dict):
            for name, w in weights.items():
                new[self.channel_index(name)] = w
        else:
            new[:] = np.asarray(weights, dtype=np.float32)
        if np.any(~np.isfinite(new)) or np.any(new < 0):
            raise ValueError(f"feature weights must be finite and >= 0, got {new.tolist()}")
        if np.array_equal(new, self.weights):
            return False
        self.weights = new.astype(np.float32)
        self._rescale()
        return True

    def normalize(self, raw: np.ndarray) -> np.ndarray:
        return normalize_with(raw, self.mean, self.inv_scale)

    def denormalize(self, x: np.ndarray) -> np.ndarray:
        """Inverse of normalize for channels with non-zero weight (zero-weight dims come back as the mean)."""
        safe = np.where(self.inv_scale > 0, self.inv_scale, 1.0)
        return np.where(self.inv_scale > 0, x / safe + self.mean, self.mean).astype(np.float32)

    def channel_costs(self, query_norm: np.ndarray, frames_norm: np.ndarray) -> np.ndarray:
        """Per-channel squared distances, (..., C)."""
        d2 = (frames_norm - query_norm) ** 2
        return np.stack([d2[..., s].sum(-1) for s in self.slices], axis=-1)

    def layout_dicts(self) -> list[dict]:
        return [replace(ch, weight=float(w)).to_dict() for ch, w in zip(self.layout, self.weights)]


def build_features(db, layout: Sequence[Channel] | None = None) -> Features:
    """Features of every database frame in ``layout`` (default: the schema the database was built with,
    from its manifest's ``features``; the shipped layout for databases that declare none)."""
    if layout is None:
        schema = getattr(db, "feature_schema", None)
        layout = layout_from_schema(schema) if schema else DEFAULT_LAYOUT
    # cached beside the database file (a pass over every frame reads the whole database)
    raw = cached(db, "features", schema_of(layout), lambda: compute_raw(db, layout))
    mean = raw.mean(axis=0)
    std = raw.std(axis=0)
    slices = layout_slices(layout)
    channel_std = np.array([std[s].mean() for s in slices], dtype=np.float32)
    return Features(layout=list(layout), raw=raw, mean=mean.astype(np.float32), channel_std=channel_std)


def build_query(features: Features, current_raw: np.ndarray,
                trajectory_at: Callable[[int], tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """A raw query vector: pose channels copied from ``current_raw`` (the playing frame's features),
    trajectory channels from ``trajectory_at(offset) -> (position, direction)``, both 3-vectors in the
    simulation object's space."""
    q = np.array(current_raw, dtype=np.float32, copy=True)
    for ch, s in zip(features.layout, features.slices):
        if ch.kind == "trajectory_position":
            q[s] = np.concatenate([trajectory_at(o)[0][[0, 2]] for o in ch.offsets])
        elif ch.kind == "trajectory_direction":
            q[s] = np.concatenate([trajectory_at(o)[1][[0, 2]] for o in ch.offsets])
    return q


def trajectory_query_columns(features: Features, offset_index: dict[int, int]) -> tuple[np.ndarray, list]:
    """Where :func:`build_query` puts each trajectory number: the query dims (K,) (a slice when they are
    one run) and, for each, a
    ``(0 for a position | 1 for a direction, index of its offset in offset_index, 0 for x | 2 for z)``.
    Computed once per layout, so a tick's query is one copy and one scattered assignment."""
    dims, picks = [], []
    for ch, s in zip(features.layout, features.slices):
        if ch.kind in ("trajectory_position", "trajectory_direction"):
            which = 0 if ch.kind == "trajectory_position" else 1
            picks += [(which, offset_index[o], c) for o in ch.offsets for c in (0, 2)]
            dims += range(s.start, s.stop)
    if dims and dims == list(range(dims[0], dims[-1] + 1)):  # one run of dims (the usual layout): a slice
        return slice(dims[0], dims[-1] + 1), picks
    return np.asarray(dims, dtype=np.int64), picks


def build_query_from_columns(current_raw: np.ndarray, columns: tuple[np.ndarray, list], positions,
                             directions) -> np.ndarray:
    """:func:`build_query` with the trajectory as sequences of 3-vectors (``positions[i]``,
    ``directions[i]`` for the i-th offset) placed by ``columns`` (see :func:`trajectory_query_columns`)."""
    dims, picks = columns
    q = np.array(current_raw, dtype=np.float32, copy=True)
    both = (positions, directions)
    q[dims] = [both[which][i][c] for which, i, c in picks]  # float64 -> float32 as the channel copy does
    return q
