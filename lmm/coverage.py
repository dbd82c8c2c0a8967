"""Coverage of a motion database: where in feature space it holds motion, and how far a query is from it.

Everything here works on the database's matching features (:mod:`lmm.features`), so "far from the data"
means what it means to the search:

* :func:`fit_pca`: the principal axes (SVD) of the normalised feature vectors, weighted as the search
  weights them; :meth:`PCA.project` puts any query on the same 2D map.
* :func:`trajectory_speed_turn`: the one definition of root speed (m/s) and turning rate (deg/s) used by
  the heat map, for database frames (:func:`database_speed_turn`, from their trajectory features) and for
  a running character's query (:func:`query_speed_turn`, from its predicted trajectory seen from its
  root, exactly as its query's trajectory channels are): the distance to the first future trajectory
  point over its horizon, and the angle of the facing there over the same horizon (signed, + toward +x).
* :func:`speed_turn_heatmap`: seconds of database motion per (speed, turn rate) cell.
* :func:`channel_histograms`: per channel of the layout, a histogram of each dimension in raw units.
* :class:`DataDistance`: the nearest database frame to a query and its cost, in the units of the search
  cost (squared distance between normalised vectors, no transition bias).

numpy only; the pictures are drawn by :mod:`lmm.reporting`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lmm.errors import InputError

MAP_COMPONENTS = 2
#: heat map cells: root speed 0-5 m/s by 0.25, turning rate -360..360 deg/s by 30 (values beyond the
#: last edges count in the outermost cells)
SPEED_EDGES_M_S = tuple(float(x) for x in np.arange(0.0, 5.0 + 1e-9, 0.25))
TURN_EDGES_DEG_S = tuple(float(x) for x in np.arange(-360.0, 360.0 + 1e-9, 30.0))
#: speed classes of the map's "colour by speed" mode (m/s)
SPEED_CLASS_EDGES_M_S = (0.0, 0.3, 1.0, 2.0, 3.0, 4.0, np.inf)
HISTOGRAM_BINS = 32
#: each dimension's histogram spans these percentiles of its values (outliers count in the end bins)
HISTOGRAM_PERCENTILES = (0.5, 99.5)
UNTAGGED = "untagged"
UNITS = {"bone_position": "m", "bone_velocity": "m/s", "trajectory_position": "m", "trajectory_direction": ""}


class CoverageError(InputError):
    """Coverage cannot be computed for this data (too few frames, no trajectory channels)."""


# ---------------------------------------------------------------------------------------------------
# the map: principal component analysis
# ---------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class PCA:
    """Principal axes of a point set: ``project(x) = (x - mean) @ axes.T``."""
    mean: np.ndarray                # (D,)
    axes: np.ndarray                # (k, D) orthonormal rows, largest variance first
    variance: np.ndarray            # (k,) variance of the points along each axis
    variance_ratio: np.ndarray      # (k,) share of the total variance

    def project(self, x) -> np.ndarray:
        """``(..., D)`` -> ``(..., k)`` coordinates on the map."""
        return (np.asarray(x, np.float64) - self.mean) @ self.axes.T

    def to_dict(self) -> dict:
        return {"mean": self.mean.tolist(), "axes": self.axes.tolist(), "explained_variance": self.variance.tolist(),
                "explained_variance_ratio": self.variance_ratio.tolist()}


def fit_pca(points, n_components: int = MAP_COMPONENTS) -> PCA:
    """PCA of ``points`` (N, D): the eigenvectors of their D x D covariance, largest variance first
    (for 0.5 M frames a tenth of the time of an SVD of the centred N x D matrix, and the leading axes
    agree to rounding). Each axis' sign is fixed (its largest component positive), so the same data
    always gives the same map."""
    x = np.asarray(points, np.float64)
    if x.ndim != 2 or x.shape[0] < 2:
        raise CoverageError(f"coverage needs at least 2 feature vectors, got {x.shape[0] if x.ndim else 0}")
    k = int(min(n_components, x.shape[1]))
    mean = x.mean(axis=0)
    centred = x - mean
    values, vectors = np.linalg.eigh(centred.T @ centred)
    order = np.argsort(values)[::-1]
    var = np.maximum(values[order], 0.0) / x.shape[0]   # rounding can leave a null variance at -1e-17
    total = float(var.sum())
    axes = np.ascontiguousarray(vectors[:, order[:k]].T)
    signs = np.sign(axes[np.arange(k), np.argmax(np.abs(axes), axis=1)])
    axes *= np.where(signs == 0, 1.0, signs)[:, None]
    ratio = var[:k] / total if total > 0 else np.zeros(k)
    return PCA(mean=mean, axes=axes, variance=var[:k].copy(), variance_ratio=ratio)


def rescale_query(query_norm, from_inv_scale, to_inv_scale) -> np.ndarray:
    """A normalised query re-expressed in another normalisation of the same features (other channel
    weights): ``q * to / from`` per dimension; dimensions whose weight was 0 (no information) become
    0, the data's mean."""
    q = np.asarray(query_norm, np.float64)
    src = np.asarray(from_inv_scale, np.float64)
    ok = src > 0
    return np.where(ok, q * np.asarray(to_inv_scale, np.float64) / np.where(ok, src, 1.0), 0.0)


# ---------------------------------------------------------------------------------------------------
# root speed x turning rate
# ---------------------------------------------------------------------------------------------------

def trajectory_speed_turn(position_xz, direction_xz, horizon_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Root speed (m/s) and signed turning rate (deg/s) from the first future trajectory point
    ``position_xz`` (..., 2) and the facing there ``direction_xz`` (..., 2), both seen from the root
    (which faces +z), ``horizon_s`` seconds ahead."""
    p = np.asarray(position_xz, np.float64)
    d = np.asarray(direction_xz, np.float64)
    speed = np.linalg.norm(p, axis=-1) / horizon_s
    turn = np.degrees(np.arctan2(d[..., 0], d[..., 1])) / horizon_s
    return speed, turn


def first_trajectory_dims(layout) -> tuple[slice, slice, int]:
    """Where the first offset's trajectory position and direction sit in a feature vector, and that
    offset (frames). Raises :class:`CoverageError` when the layout lacks either channel kind."""
    start, pos, direction = 0, None, None
    for ch in layout:
        if ch.kind == "trajectory_position" and pos is None:
            pos = (slice(start, start + 2), int(ch.offsets[0]))
        elif ch.kind == "trajectory_direction" and direction is None:
            direction = (slice(start, start + 2), int(ch.offsets[0]))
        start += ch.dims
    if pos is None or direction is None:
        raise CoverageError("the speed x turn-rate map needs trajectory_position and trajectory_direction "
                            "feature channels; this feature layout has "
                            + ", ".join(ch.name for ch in layout))
    if pos[1] != direction[1]:
        raise CoverageError(f"the first trajectory position ({pos[1]} frames) and direction ({direction[1]} "
                            f"frames) offsets differ; the speed x turn-rate map needs them equal")
    return pos[0], direction[0], pos[1]


def database_speed_turn(features, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """(N,) root speed and turning rate of every database frame, from its raw trajectory features."""
    pos, direction, offset = first_trajectory_dims(features.layout)
    return trajectory_speed_turn(features.raw[:, pos], features.raw[:, direction], offset / fps)


def query_speed_turn(trajectory_positions, trajectory_rotations, trajectory_offsets, root_position,
                     root_rotation, offset: int, fps: float) -> tuple[float, float]:
    """Root speed and turning rate a running character asks for: its predicted trajectory (world, at
    ``trajectory_offsets`` frames ahead) seen from its root, as its query's trajectory channels are."""
    from lmm.trajectory import trajectory_in_root_space

    offsets = [int(o) for o in np.asarray(trajectory_offsets)]
    if offset not in offsets:
        return float("nan"), float("nan")
    i = offsets.index(offset)
    (lp,), (ld,) = trajectory_in_root_space(
        [tuple(np.asarray(trajectory_positions, np.float64)[i].tolist())],
        [tuple(np.asarray(trajectory_rotations, np.float64)[i].tolist())],
        tuple(np.asarray(root_position, np.float64).tolist()), tuple(np.asarray(root_rotation, np.float64).tolist()))
    speed, turn = trajectory_speed_turn(np.array([lp[0], lp[2]]), np.array([ld[0], ld[2]]), offset / fps)
    return float(speed), float(turn)


@dataclass
class Heatmap:
    speed_edges_m_s: np.ndarray     # (S + 1,)
    turn_edges_deg_s: np.ndarray    # (T + 1,)
    seconds: np.ndarray             # (S, T) seconds of database motion per cell
    horizon_frames: int = 0

    def cell(self, speed: float, turn: float) -> tuple[int, int]:
        """The (row, column) a speed and turning rate fall in (clamped to the outermost cells)."""
        se, te = self.speed_edges_m_s, self.turn_edges_deg_s
        i = int(np.clip(np.searchsorted(se, speed, side="right") - 1, 0, len(se) - 2))
        j = int(np.clip(np.searchsorted(te, turn, side="right") - 1, 0, len(te) - 2))
        return i, j

    def seconds_at(self, speed: float, turn: float) -> float:
        """Seconds of database motion in the cell of ``(speed, turn)`` (nan for a nan query)."""
        if not (np.isfinite(speed) and np.isfinite(turn)):
            return float("nan")
        return float(self.seconds[self.cell(speed, turn)])

    def to_dict(self) -> dict:
        return {"speed_edges_m_s": self.speed_edges_m_s.tolist(), "turn_edges_deg_s": self.turn_edges_deg_s.tolist(),
                "seconds": np.round(self.seconds, 3).tolist(), "horizon_frames": self.horizon_frames,
                "rows": "speed", "columns": "turn rate (signed, + toward +x)"}


def speed_turn_heatmap(speed, turn, fps: float, speed_edges=SPEED_EDGES_M_S, turn_edges=TURN_EDGES_DEG_S,
                       horizon_frames: int = 0) -> Heatmap:
    """Seconds of frames per (speed, turn rate) cell; values beyond the edges count in the outer cells."""
    se, te = np.asarray(speed_edges, np.float64), np.asarray(turn_edges, np.float64)
    s = np.clip(np.asarray(speed, np.float64), se[0], np.nextafter(se[-1], -np.inf))
    t = np.clip(np.asarray(turn, np.float64), te[0], np.nextafter(te[-1], -np.inf))
    counts, _, _ = np.histogram2d(s, t, bins=[se, te])
    return Heatmap(se, te, counts / fps, int(horizon_frames))


# ---------------------------------------------------------------------------------------------------
# per-channel histograms
# ---------------------------------------------------------------------------------------------------

@dataclass
class ChannelHistogram:
    name: str
    unit: str
    dims: list[str]                 # label of each dimension ("x", "z+20", ...)
    edges: np.ndarray               # (dims, bins + 1) raw units
    counts: np.ndarray              # (dims, bins) frames

    def to_dict(self) -> dict:
        return {"channel": self.name, "unit": self.unit, "dims": self.dims, "edges": np.round(self.edges, 5).tolist(),
                "counts": self.counts.astype(int).tolist()}


def dim_labels(channel) -> list[str]:
    if channel.kind.startswith("bone"):
        return ["x", "y", "z"]
    return [f"{axis}+{o}" for o in channel.offsets for axis in ("x", "z")]


def channel_histograms(features, bins: int = HISTOGRAM_BINS) -> list[ChannelHistogram]:
    """For every channel, each dimension's histogram of the database's raw values, over the central
    ``HISTOGRAM_PERCENTILES`` of them (values outside count in the end bins)."""
    raw = np.asarray(features.raw, np.float64)
    lo, hi = np.percentile(raw, HISTOGRAM_PERCENTILES, axis=0)
    out = []
    for ch, s in zip(features.layout, features.slices):
        edges, counts = [], []
        for d in range(s.start, s.stop):
            a, b = float(lo[d]), float(hi[d])
            if not b > a:
                a, b = a - 0.5, a + 0.5
            e = np.linspace(a, b, bins + 1)
            c, _ = np.histogram(np.clip(raw[:, d], a, np.nextafter(b, -np.inf)), bins=e)
            edges.append(e)
            counts.append(c)
        out.append(ChannelHistogram(ch.name, UNITS.get(ch.kind, ""), dim_labels(ch), np.array(edges), np.array(counts)))
    return out


# ---------------------------------------------------------------------------------------------------
# frame categories (map colours)
# ---------------------------------------------------------------------------------------------------

def frame_tag_categories(db) -> tuple[list[str], np.ndarray]:
    """Each frame's most specific tag: of its range's tags the one on the fewest database frames
    (``walk, strafe, turn`` -> ``strafe`` when strafing is rarer than walking), ``untagged`` when the
    range has none. Returns the names (sorted, ``untagged`` last) and a (N,) index into them."""
    lengths = np.asarray(db.range_stops) - np.asarray(db.range_starts)
    range_tags = list(db.range_tags) if db.range_tags else [()] * db.n_ranges
    frames_of: dict[str, int] = {}
    for tags, n in zip(range_tags, lengths):
        for t in tags:
            frames_of[t] = frames_of.get(t, 0) + int(n)
    chosen = [min(tags, key=lambda t: (frames_of[t], t)) if tags else UNTAGGED for tags in range_tags]
    names = sorted(set(chosen), key=lambda t: (t == UNTAGGED, t))
    per_range = np.array([names.index(t) for t in chosen], dtype=np.int64)
    return names, np.repeat(per_range, lengths)


def speed_categories(speed, edges=SPEED_CLASS_EDGES_M_S) -> tuple[list[str], np.ndarray]:
    """Speed classes: the labels (``0-0.3 m/s`` ... ``4+ m/s``) and each frame's class index."""
    e = np.asarray(edges, np.float64)
    labels = [f"{e[i]:g}+ m/s" if not np.isfinite(e[i + 1]) else f"{e[i]:g}-{e[i + 1]:g} m/s"
              for i in range(len(e) - 1)]
    idx = np.clip(np.searchsorted(e, np.asarray(speed, np.float64), side="right") - 1, 0, len(labels) - 1)
    return labels, idx.astype(np.int64)


def subsample(n: int, max_points: int) -> np.ndarray:
    """Evenly spaced indices of at most ``max_points`` of ``n`` items (all when fewer)."""
    if n <= max_points:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, max_points).round().astype(np.int64))


# ---------------------------------------------------------------------------------------------------
# distance to the data
# ---------------------------------------------------------------------------------------------------

class DataDistance:
    """Nearest database frame to a normalised query, cost in search units (``sum (q - x)^2``, as
    :func:`lmm.search.frame_costs` computes it): every frame is a candidate, no transition bias.

    Exact, through the search's own bounding-box index (:class:`lmm.search.SearchIndex`), seeded with
    the previous answer; one instance must not be used from two threads at once."""

    def __init__(self, normalized):
        from lmm.search import SearchIndex

        points = np.ascontiguousarray(normalized, np.float32)
        self.n_frames = len(points)
        self.index = SearchIndex(points) if self.n_frames else None
        self.every = np.ones(self.n_frames, dtype=bool)   # every frame a candidate
        self.mask = self.every        # the candidates (a caller may set a narrower mask of its own)
        self._hint: np.ndarray | None = None

    def nearest(self, query) -> tuple[int, float]:
        """(frame, cost); (-1, nan) for a query that is not finite or an empty database."""
        q = np.asarray(query, np.float32)
        if self.index is None or not np.all(np.isfinite(q)):
            return -1, float("nan")
        r = self.index.search(q, self.mask, top_k=1, hint=self._hint)
        self._hint = r.frames[:1].copy()
        return r.best_frame, r.best_cost


# ---------------------------------------------------------------------------------------------------
# everything at once
# ---------------------------------------------------------------------------------------------------

@dataclass
class Coverage:
    """The coverage of one database under one feature normalisation."""
    pca: PCA
    map_xy: np.ndarray              # (N, 2) every frame on the map
    speed_m_s: np.ndarray           # (N,)
    turn_deg_s: np.ndarray          # (N,)
    heatmap: Heatmap
    histograms: list[ChannelHistogram]
    tag_names: list[str]
    frame_tag: np.ndarray           # (N,) index into tag_names (see frame_tag_categories)
    inv_scale: np.ndarray           # (D,) the normalisation the map was made with
    channel_names: list[str] = field(default_factory=list)
    fps: float = 60.0

    @property
    def n_frames(self) -> int:
        return int(self.map_xy.shape[0])

    def project_query(self, query_norm, query_inv_scale=None) -> np.ndarray:
        """A normalised query (normalised with ``query_inv_scale``, default the map's own) on the map."""
        q = np.asarray(query_norm, np.float64)
        if query_inv_scale is not None:
            q = rescale_query(q, query_inv_scale, self.inv_scale)
        return self.pca.project(q)

    def map_density(self, bins: int = 48) -> dict:
        (x0, y0), (x1, y1) = self.map_xy.min(axis=0), self.map_xy.max(axis=0)
        counts, xe, ye = np.histogram2d(self.map_xy[:, 0], self.map_xy[:, 1], bins=bins,
                                        range=[[x0, x1 + 1e-9], [y0, y1 + 1e-9]])
        return {"x_edges": np.round(xe, 5).tolist(), "y_edges": np.round(ye, 5).tolist(),
                "counts": counts.astype(int).tolist()}

    def to_dict(self) -> dict:
        tag_frames = np.bincount(self.frame_tag, minlength=len(self.tag_names))
        return {
            "frames": self.n_frames, "fps": self.fps, "channels": self.channel_names,
            "dims": [f"{h.name}.{label}" for h in self.histograms for label in h.dims],
            "pca": self.pca.to_dict(), "map_density": self.map_density(),
            "seconds_per_map_tag": {t: round(int(n) / self.fps, 3) for t, n in zip(self.tag_names, tag_frames)},
            "speed_turn": self.heatmap.to_dict(),
            "histograms": [h.to_dict() for h in self.histograms],
        }


def build_coverage(db, features) -> Coverage:
    """The coverage of ``db`` under ``features``' current normalisation and weights."""
    pca = fit_pca(features.normalized)
    speed, turn = database_speed_turn(features, db.fps)
    _, _, offset = first_trajectory_dims(features.layout)
    names, tag_index = frame_tag_categories(db)
    return Coverage(pca=pca, map_xy=pca.project(features.normalized), speed_m_s=speed, turn_deg_s=turn,
                    heatmap=speed_turn_heatmap(speed, turn, db.fps, horizon_frames=offset),
                    histograms=channel_histograms(features), tag_names=names, frame_tag=tag_index,
                    inv_scale=np.array(features.inv_scale, np.float64), channel_names=list(features.names),
                    fps=float(db.fps))
