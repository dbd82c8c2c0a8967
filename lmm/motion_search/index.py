"""The motion search index: every window of every take, embedded, searched by example and re-ranked by DTW.

**What is indexed.** The takes of a manifest (its files, whole takes, each once; ``file`` as written in the
manifest) or every ``.bvh`` under a folder (``file`` relative to the folder), reduced to key-joint frames
at :data:`~lmm.motion_search.windows.WINDOW_FPS` (:func:`~lmm.motion_search.windows.take_frames`), with a
window starting at every resampled frame. An embedder (:mod:`lmm.motion_search.embed`) turns each window
into a vector: by default the learned encoder when its weights ``lmm/data/weights/search_encoder.npz``
are shipped, else the plain features baseline scaled by the index's own feature spreads.

**Cache.** Building means reading every file and embedding every window, so the result is kept on disk
under ``<cache>/motion_search/`` (written atomically), named by a hash of each file's path, size and
modification time, the embedder (its name and a hash of its parameters) and the window settings. A
changed file, embedder or setting is a new name; a cache file that cannot be read is rebuilt.

**Search.** A query is key-joint frames of any length >= :data:`MIN_QUERY_FRAMES` (from a BVH frame range,
a manifest range or the studio's history). Up to 48 frames it is resampled to one window; a longer query
is cut into up to 8 overlapping windows whose hits vote for the start they imply. Exact k-NN over the
embeddings gives candidates, near-duplicates are suppressed (non-maximum suppression within half a window
of the same file), and the best :data:`RERANK_TOP` are re-ranked by DTW (:mod:`lmm.motion_search.dtw`)
between the query's frames and the candidate's segments of 0.7x..1.4x the query's length, so the same
motion at another speed still ranks first. Results are in each file's own frame numbers.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lmm.errors import InputError
from lmm.motion_search.dtw import dtw_distances
from lmm.motion_search.embed import FeatureEmbedder, knn
from lmm.motion_search.windows import (FRAME_DIM, KEY_JOINTS, frame_ratio, WINDOW_FPS, WINDOW_FRAMES, frame_features, match_key_joints,
                                       resample, take_frames, windows)

INDEX_VERSION = 2
MIN_QUERY_FRAMES = 8                      # at 30 fps: 0.27 s, about one foot contact
SINGLE_WINDOW_MAX_FRAMES = 48             # longer queries are cut into overlapping windows
MAX_QUERY_WINDOWS = 8
RERANK_TOP = 50                           # candidates re-ranked by DTW
WARP_FACTORS = (0.7, 0.85, 1.0, 1.2, 1.4)  # candidate segment length / query length
START_SHIFTS = (-0.1, 0.0, 0.1)           # candidate start moved by this fraction of the query length
DTW_BAND = 0.15                           # Sakoe-Chiba half-width, fraction of the query length
DTW_MAX_FRAMES = 48                       # longer queries and segments are compared every 2nd (3rd...) frame
FAST_KNN_MAX_QUERIES = 64
EMBED_CHUNK = 8192                        # windows embedded at once (memory: chunk x 32 x 19 floats)
ENCODER_WEIGHTS = "search_encoder.npz"


class SearchError(InputError):
    """A query or a set of takes the search cannot use (names the file)."""


@dataclass(frozen=True)
class Source:
    """One file to index: ``label`` as the user gave it (manifest entry or path relative to the folder)."""
    label: str
    path: Path


@dataclass
class Match:
    file: str             # the source's label
    start_frame: int      # in the file's own frame numbers, [start_frame, end_frame)
    end_frame: int
    distance: float       # DTW distance per frame pair (after re-ranking), else the embedding distance
    take: int             # index into MotionIndex.sources
    start: int            # resampled (WINDOW_FPS) frame where the match starts in that take
    length: int           # resampled frames
    embedding_distance: float = float("nan")

    def to_dict(self) -> dict:
        return {"file": self.file, "start_frame": self.start_frame, "end_frame": self.end_frame,
                "distance": round(float(self.distance), 6)}


# --- what to index -------------------------------------------------------------------------------------

def sources_from_manifest(path) -> list[Source]:
    """The manifest's files (each once, in manifest order), labelled as the manifest writes them."""
    from lmm.data.manifest import load_manifest

    manifest = load_manifest(path)
    seen, out = set(), []
    for clip in manifest.clips:
        key = os.path.realpath(clip.file)
        if key not in seen:
            seen.add(key)
            out.append(Source(clip.source or clip.file.name, Path(clip.file)))
    if not out:
        raise SearchError(f"{path}: the manifest lists no takes")
    return out


def sources_from_folder(path) -> list[Source]:
    """Every ``.bvh``, ``.glb``, ``.gltf`` and ``.fbx`` file under ``path`` (any depth, sorted), labelled relative to it."""
    root = Path(path)
    if not root.is_dir():
        raise SearchError(f"{path}: not a folder")
    files = sorted(p for p in root.rglob("*") if p.suffix.lower() in (".bvh", ".glb", ".gltf", ".fbx") and p.is_file())
    if not files:
        raise SearchError(f"{path}: the folder holds no .bvh files (nor .glb, .gltf or .fbx)")
    return [Source(p.relative_to(root).as_posix(), p) for p in files]


def sources_from(path) -> list[Source]:
    """A folder of BVH files or a manifest."""
    p = Path(path)
    if p.is_dir():
        return sources_from_folder(p)
    if not p.exists():
        raise SearchError(f"{path}: no such manifest or folder")
    return sources_from_manifest(p)


# --- queries -------------------------------------------------------------------------------------------

def _check_query(frames: np.ndarray, where: str) -> np.ndarray:
    frames = np.asarray(frames, np.float32)
    if frames.ndim != 2 or frames.shape[1] != FRAME_DIM:
        raise SearchError(f"{where}: a query is (frames, {FRAME_DIM}) key-joint features, got {frames.shape}")
    if len(frames) < MIN_QUERY_FRAMES:
        raise SearchError(f"{where}: the query is {len(frames)} frames at {WINDOW_FPS:g} fps; "
                          f"at least {MIN_QUERY_FRAMES} are needed")
    if not np.isfinite(frames).all():
        raise SearchError(f"{where}: the query holds NaN or infinite values")
    return frames


def query_from_bvh(path, frames: tuple[int, int] | None = None) -> np.ndarray:
    """Key-joint frames of file frames ``[a, b)`` of a BVH file (the whole take when ``frames`` is None).

    The features are computed over the whole take and then cut, so that velocities at the range's ends
    and the size reference are the take's (a range cut from an indexed take is exactly its frames)."""
    from lmm.data.motion_files import load_motion

    anim = load_motion(path)
    n = anim.n_frames
    a, b = (0, n) if frames is None else (int(frames[0]), int(frames[1]))
    if a >= b:
        raise SearchError(f"{path}: frames {a}:{b} are an empty range")
    if b > n:
        raise SearchError(f"{path}: frames {a}:{b} go past the end of the take ({n} frames, 0:{n})")
    tf = take_frames(anim, str(path))
    ratio = frame_ratio(tf.file_fps)
    i0, i1 = (math.ceil(a / ratio - 1e-9), math.ceil(b / ratio - 1e-9))
    return _check_query(tf.frames[i0:i1], f"{path} frames {a}:{b}")


def query_from_manifest_range(manifest, clip: int, range_index: int = 0) -> np.ndarray:
    """Key-joint frames of range ``range_index`` of clip ``clip`` of a parsed manifest."""
    c = manifest.clips[clip]
    frames = None if c.ranges is None else tuple(c.ranges[range_index])
    return query_from_bvh(c.file, frames)


def query_from_positions(key_positions: np.ndarray, fps: float, ref_height: float | None = None,
                         where: str = "query") -> np.ndarray:
    """Key-joint frames of ``(F, 6, 3)`` world positions in KEY_JOINTS order sampled at ``fps``.

    ``ref_height``: the character's standing hips height in the positions' unit (the unit of every
    feature). Pass it whenever it is known: a short window's own estimate is wrong when the window
    crouches, lies or jumps. None: estimated from the window."""
    kp = np.asarray(key_positions, np.float64)
    if kp.ndim != 3 or kp.shape[1:] != (6, 3):
        raise SearchError(f"{where}: key-joint positions must be (frames, 6, 3), got {kp.shape}")
    return _check_query(resample(frame_features(kp, fps, ref_height), fps), where)


def query_from_skeleton(names, global_positions: np.ndarray, fps: float, ref_height: float | None = None,
                        where: str = "the character") -> np.ndarray:
    """Key-joint frames of ``(F, J, 3)`` global positions of a skeleton whose joints are ``names`` (the
    studio's history of a character); ``ref_height`` as in :func:`query_from_positions`."""
    keys = match_key_joints(names, where)
    g = np.asarray(global_positions)
    return query_from_positions(g[:, [keys[k] for k in KEY_JOINTS]], fps, ref_height, where)


def resample_length(frames: np.ndarray, n: int) -> np.ndarray:
    """``frames`` stretched or squeezed to ``n`` frames by linear interpolation (both ends kept)."""
    frames = np.asarray(frames, np.float32)
    F = len(frames)
    if F == n:
        return frames
    t = np.linspace(0.0, F - 1, n)
    i0 = np.minimum(np.floor(t).astype(int), F - 1)
    i1 = np.minimum(i0 + 1, F - 1)
    w = (t - i0)[:, None].astype(np.float32)
    return (1.0 - w) * frames[i0] + w * frames[i1]


def query_windows(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The windows a query is searched with and their start in the query: one resampled window up to
    :data:`SINGLE_WINDOW_MAX_FRAMES` frames, else up to :data:`MAX_QUERY_WINDOWS` overlapping windows."""
    L = len(frames)
    if L <= SINGLE_WINDOW_MAX_FRAMES:
        return resample_length(frames, WINDOW_FRAMES)[None], np.zeros(1, np.int64)
    n = min(MAX_QUERY_WINDOWS, math.ceil((L - WINDOW_FRAMES) / (WINDOW_FRAMES // 2)) + 1)
    offsets = np.unique(np.rint(np.linspace(0, L - WINDOW_FRAMES, n)).astype(np.int64))
    return np.stack([frames[o:o + WINDOW_FRAMES] for o in offsets]), offsets


# --- the embedder --------------------------------------------------------------------------------------

def default_encoder_path() -> Path:
    from lmm import DATA_DIR

    return Path(DATA_DIR) / "weights" / ENCODER_WEIGHTS


def default_embedder():
    """The learned encoder when its weights are shipped, else None (the features baseline fitted on the
    index)."""
    if not default_encoder_path().is_file():
        return None
    try:
        from lmm.motion_search.encoder import load_default
    except ImportError:
        return None
    return load_default()


def _hash_value(h, value, depth: int = 0) -> None:
    if isinstance(value, np.ndarray):
        h.update(f"{value.dtype.str}{value.shape}".encode())
        h.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, (str, int, float, bool, type(None))):
        h.update(repr(value).encode())
    elif isinstance(value, (list, tuple)):
        for v in value:
            _hash_value(h, v, depth + 1)
    elif isinstance(value, dict):
        for k in sorted(value, key=str):
            h.update(str(k).encode())
            _hash_value(h, value[k], depth + 1)
    elif depth < 4 and hasattr(value, "__dict__"):
        h.update(type(value).__name__.encode())
        _hash_value(h, vars(value), depth + 1)


def embedder_identity(embedder) -> str:
    """``name:hash`` of an embedder's parameters (its ``cache_key`` when it has one): part of the cache name."""
    key = getattr(embedder, "cache_key", None)
    if key:
        return f"{embedder.name}:{key}"
    h = hashlib.sha256()
    _hash_value(h, vars(embedder) if hasattr(embedder, "__dict__") else {})
    return f"{embedder.name}:{h.hexdigest()[:16]}"


# --- the index -----------------------------------------------------------------------------------------

def default_cache_folder() -> Path:
    from lmm.data.cache import default_cache_dir

    return Path(default_cache_dir()) / "motion_search"


def _file_stamp(path: Path, label: str) -> list:
    try:
        st = os.stat(path)
    except OSError as e:
        raise SearchError(f"{label}: cannot read the file ({e.strerror or e})") from None
    return [label, os.path.realpath(path), st.st_size, st.st_mtime_ns]


@dataclass
class MotionIndex:
    sources: list[Source]
    file_fps: np.ndarray          # (T,)
    n_file_frames: np.ndarray     # (T,)
    take_offsets: np.ndarray      # (T + 1,) row offsets of each take in ``frames``
    frames: np.ndarray            # (N, FRAME_DIM) key-joint frames of every take, concatenated
    window_take: np.ndarray       # (W,) int32
    window_start: np.ndarray      # (W,) int32, resampled frame in its take
    embeddings: np.ndarray        # (W, dim) float32
    scale: np.ndarray             # (FRAME_DIM,) feature spreads (DTW compares frames divided by them)
    embedder: object
    cache_path: Path | None = None
    from_cache: bool = False
    build_seconds: float = 0.0
    _norms: np.ndarray | None = field(default=None, repr=False)

    # -- building --
    @classmethod
    def build(cls, sources: list[Source], embedder=None, cache_dir=None, use_cache: bool = True,
              rebuild: bool = False, progress=None) -> "MotionIndex":
        """The index of ``sources`` (from the cache when its files, embedder and settings are unchanged;
        ``rebuild``: computed again and stored; ``use_cache`` False: neither read nor written).
        ``embedder`` None: :func:`default_embedder`, else the features baseline fitted on the index.
        ``progress(done, total, label)`` is called while building: once at the start (``done`` 0), then
        after each file read, each take embedded and the cache written (``total`` = 2 x files + 1)."""
        t0 = time.perf_counter()
        if not sources:
            raise SearchError("nothing to search: no files given")
        if embedder is None:
            embedder = default_embedder()
        fitted_features = embedder is None
        identity = (f"features-fitted:step={FeatureEmbedder().step}" if fitted_features
                    else embedder_identity(embedder))
        key = {"version": INDEX_VERSION, "window": [WINDOW_FPS, WINDOW_FRAMES, FRAME_DIM],
               "embedder": identity, "files": [_file_stamp(s.path, s.label) for s in sources]}
        digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:24]
        folder = Path(cache_dir) if cache_dir is not None else default_cache_folder()
        path = folder / f"index-{digest}.npz"
        if use_cache and not rebuild and path.is_file():
            loaded = cls._load(path, sources, embedder, fitted_features)
            if loaded is not None:
                loaded.build_seconds = time.perf_counter() - t0
                return loaded
        index = cls._compute(sources, embedder, fitted_features, progress)
        index.cache_path = path
        if use_cache:
            index._save(path, identity)
        if progress:
            progress(*_build_steps(len(sources), "saved" if use_cache else "done"))
        index.build_seconds = time.perf_counter() - t0
        return index

    @classmethod
    def _compute(cls, sources, embedder, fitted_features, progress) -> "MotionIndex":
        from lmm.data.motion_files import load_motion

        n_src = len(sources)
        total = _build_steps(n_src)[1]
        if progress:
            progress(0, total, "reading")
        fps, counts, per_take = [], [], []
        for i, s in enumerate(sources):
            anim = load_motion(s.path)
            tf = take_frames(anim, s.label)
            fps.append(tf.file_fps)
            counts.append(tf.n_file_frames)
            per_take.append(tf.frames)
            if progress:
                progress(i + 1, total, f"read {s.label}")
        lengths = np.array([len(f) for f in per_take], np.int64)
        offsets = np.concatenate([[0], np.cumsum(lengths)])
        frames = np.concatenate(per_take).astype(np.float32)
        n_windows = np.maximum(lengths - WINDOW_FRAMES + 1, 0)
        if n_windows.sum() == 0:
            raise SearchError(f"{sources[0].label}: no take is as long as one search window "
                              f"({WINDOW_FRAMES} frames at {WINDOW_FPS:g} fps)")
        window_take = np.repeat(np.arange(len(sources), dtype=np.int32), n_windows)
        window_start = np.concatenate([np.arange(n, dtype=np.int32) for n in n_windows])
        scale = np.maximum(frames.astype(np.float64).std(axis=0), 1e-3).astype(np.float32)
        if fitted_features:
            embedder = FeatureEmbedder(scale=scale)
        chunks = []
        for t, f in enumerate(per_take):
            w = windows(f)
            for a in range(0, len(w), EMBED_CHUNK):
                chunks.append(np.asarray(embedder.embed(w[a:a + EMBED_CHUNK]), np.float32))
            if progress:
                progress(n_src + t + 1, total, f"embedded {sources[t].label}")
        embeddings = np.ascontiguousarray(np.concatenate(chunks))
        return cls(list(sources), np.array(fps, np.float64), np.array(counts, np.int64), offsets, frames,
                   window_take, window_start, embeddings, scale, embedder)

    def _save(self, path: Path, identity: str) -> None:
        from lmm.data import archive

        meta = {"version": INDEX_VERSION, "embedder": identity, "labels": [s.label for s in self.sources]}
        try:
            archive.write(path, {k: getattr(self, k) for k in _CACHED_ARRAYS}, meta)
        except OSError:
            pass  # a read-only cache only costs the next build its time

    @classmethod
    def _load(cls, path: Path, sources, embedder, fitted_features) -> "MotionIndex | None":
        from lmm.data import archive

        try:
            with archive.read(path, what="search index cache") as r:
                r.refuse_unknown(_CACHED_ARRAYS)
                meta = r.metadata()
                arrays = {k: r.array(k) for k in _CACHED_ARRAYS}
        except archive.ArchiveError:  # a damaged or older cache file is rebuilt, never an error
            return None
        if not isinstance(meta, dict):
            return None
        if meta.get("labels") != [s.label for s in sources] or meta.get("version") != INDEX_VERSION:
            return None
        n_takes, n_windows = len(sources), len(arrays["window_take"])
        if (len(arrays["take_offsets"]) != n_takes + 1 or len(arrays["embeddings"]) != n_windows
                or arrays["frames"].shape[1:] != (FRAME_DIM,)):
            return None
        if fitted_features:
            embedder = FeatureEmbedder(scale=arrays["scale"])
        return cls(list(sources), embedder=embedder, cache_path=path, from_cache=True, **arrays)

    # -- reading --
    @property
    def n_windows(self) -> int:
        return len(self.window_take)

    def take(self, t: int) -> np.ndarray:
        """Resampled key-joint frames of take ``t``."""
        return self.frames[self.take_offsets[t]:self.take_offsets[t + 1]]

    def source_of(self, path) -> int | None:
        """The index of the take read from ``path`` (same file on disk), or None."""
        try:
            real = os.path.realpath(path)
        except (OSError, ValueError):
            return None
        return next((i for i, s in enumerate(self.sources) if os.path.realpath(s.path) == real), None)

    def query_range(self, t: int, frames: tuple[int, int] | None, where: str | None = None) -> np.ndarray:
        """Key-joint frames of file frames ``[a, b)`` of indexed take ``t``: what :func:`query_from_bvh`
        gives for that file, without reading it again."""
        where = where or self.sources[t].label
        n = int(self.n_file_frames[t])
        a, b = (0, n) if frames is None else (int(frames[0]), int(frames[1]))
        if a >= b:
            raise SearchError(f"{where}: frames {a}:{b} are an empty range")
        if b > n:
            raise SearchError(f"{where}: frames {a}:{b} go past the end of the take ({n} frames, 0:{n})")
        i0, i1 = self.resampled_range(t, (a, b))
        return _check_query(self.take(t)[i0:i1], f"{where} frames {a}:{b}")

    def resampled_range(self, t: int, frames: tuple[int, int]) -> tuple[int, int]:
        """File frames ``[a, b)`` of take ``t`` as resampled frames ``[i0, i1)`` (the ``exclude`` of
        :meth:`search` for a query cut from this take)."""
        ratio = frame_ratio(self.file_fps[t])
        return math.ceil(frames[0] / ratio - 1e-9), math.ceil(frames[1] / ratio - 1e-9)

    def file_frame(self, t: int, resampled) -> int:
        return int(round(float(resampled) * frame_ratio(self.file_fps[t])))

    def nearest_windows(self, vectors: np.ndarray, k: int):
        """``(indices, distances)`` of the ``k`` nearest window embeddings of each of ``vectors``, exact.

        A query's few vectors use the embeddings' squared norms computed once per index (the
        distance is then one matrix product and one partition); larger batches go through the chunked
        :func:`~lmm.motion_search.embed.knn`. (faiss-cpu's exact flat index was measured no faster at
        the 27 shared takes' 125k windows: bench/find_latency.py.)"""
        q = np.ascontiguousarray(vectors, np.float32)
        k = max(0, min(int(k), self.n_windows))
        if len(q) > FAST_KNN_MAX_QUERIES or k == 0:
            return knn(self.embeddings, q, k)
        if self._norms is None:
            self._norms = np.einsum("ij,ij->i", self.embeddings, self.embeddings)
        d2 = self._norms[None, :] - 2.0 * (q @ self.embeddings.T)
        idx = np.argpartition(d2, k - 1, axis=1)[:, :k]
        part = np.take_along_axis(d2, idx, axis=1)
        order = np.argsort(part, axis=1, kind="stable")
        idx = np.take_along_axis(idx, order, axis=1)
        d2 = np.take_along_axis(part, order, axis=1) + np.einsum("ij,ij->i", q, q)[:, None]
        return idx.astype(np.int64), np.sqrt(np.maximum(d2, 0.0))

    # -- searching --
    def search(self, query: np.ndarray, top: int = 10, rerank: int = RERANK_TOP, dtw_backend: str = "auto",
               exclude: tuple[int, int, int] | None = None) -> list[Match]:
        """The ``top`` best matches of ``query`` (key-joint frames at WINDOW_FPS), best first.

        ``rerank`` 0 keeps the embedding order (no DTW). ``exclude`` ``(take, start, end)`` in resampled
        frames drops candidates overlapping it (a query cut from the index itself)."""
        q = _check_query(query, "query")
        L = len(q)
        qwin, offsets = query_windows(q)
        vectors = np.asarray(self.embedder.embed(qwin), np.float32)
        pool = max(top, rerank) * 4
        idx, dist = self.nearest_windows(vectors, pool)
        # each hit votes for the start of the whole query that it implies
        takes = self.window_take[idx].astype(np.int64)
        starts = np.maximum(self.window_start[idx].astype(np.int64) - offsets[:, None], 0)
        order = np.argsort(dist.ravel(), kind="stable")
        cand = _suppress(takes.ravel()[order], starts.ravel()[order], dist.ravel()[order],
                         max(top, rerank if rerank > 0 else top), WINDOW_FRAMES // 2,
                         exclude, L)
        if rerank <= 0 or not cand:
            return [self._match(t, s, L, d, d) for t, s, d in cand[:top]]
        reranked = self._rerank(q, cand[:rerank], dtw_backend)
        # after re-ranking a start may move by a tenth of the query: suppress within half the query
        final = _suppress(np.array([r[0] for r in reranked]), np.array([r[1] for r in reranked]),
                          np.array([r[3] for r in reranked]), top, max(WINDOW_FRAMES, L) // 2, exclude,
                          np.array([r[2] for r in reranked]))
        by_key = {(r[0], r[1]): r for r in reranked}
        return [self._match(t, s, by_key[(t, s)][2], d, by_key[(t, s)][4]) for t, s, d in final]

    def _rerank(self, q: np.ndarray, cand, backend: str) -> list:
        """``[(take, start, length, dtw distance, embedding distance)]`` of each candidate at its best
        length and start shift."""
        L = len(q)
        step = max(1, math.ceil(L / DTW_MAX_FRAMES))   # DTW cost grows with the square of the length
        qs = q[::step] / self.scale
        band = max(2, int(round(DTW_BAND * len(qs))))
        best = {i: (math.inf, c[1], L) for i, c in enumerate(cand)}
        for factor in WARP_FACTORS:
            m = max(2, int(round(L * factor)))
            segs, who = [], []
            for i, (t, s, _) in enumerate(cand):
                frames = self.take(t)
                for shift in START_SHIFTS:
                    a = min(int(s + round(shift * L)), len(frames) - m)
                    if a < 0:
                        continue
                    segs.append(frames[a:a + m])
                    who.append((i, a))
            if not segs:
                continue
            seg = np.stack(segs)[:, ::step] / self.scale
            # per query frame: dividing by the path or segment length would favour longer segments
            d = dtw_distances(qs, seg, band, backend) / math.sqrt(len(qs))
            for (i, a), v in zip(who, d):
                if v < best[i][0]:
                    best[i] = (float(v), a, m)
        out = []
        for i, (t, s, e) in enumerate(cand):
            v, a, m = best[i]
            if math.isfinite(v):
                out.append((t, a, m, v, e))
        out.sort(key=lambda r: r[3])
        return out

    def _match(self, t: int, start: int, length: int, distance: float, embedding_distance: float) -> Match:
        t = int(t)
        a = self.file_frame(t, start)
        b = min(max(self.file_frame(t, start + length), a + 1), int(self.n_file_frames[t]))
        return Match(self.sources[t].label, a, b, float(distance), t, int(start), int(length),
                     float(embedding_distance))


def _build_steps(n_sources: int, label: str = "") -> tuple[int, int, str]:
    """``(done, total, label)`` of a finished build: each file read, each take embedded, the cache written
    are one step each, so a progress bar moves during every phase (the embedding is most of the time)."""
    total = 2 * n_sources + 1
    return total, total, label


#: the arrays of a :class:`MotionIndex` its cache file holds
_CACHED_ARRAYS = ("file_fps", "n_file_frames", "take_offsets", "frames", "window_take", "window_start", "embeddings",
                  "scale")


def _suppress(takes, starts, dists, k: int, radius: int, exclude, lengths) -> list[tuple[int, int, float]]:
    """Greedy non-maximum suppression over hits sorted best first: keep a hit unless a kept one in the
    same take starts within ``radius`` frames; drop hits overlapping ``exclude`` ``(take, start, end)``."""
    kept: dict[int, list[int]] = {}
    out = []
    lengths = np.broadcast_to(np.asarray(lengths), np.shape(takes))
    for t, s, d, n in zip(np.asarray(takes).tolist(), np.asarray(starts).tolist(), np.asarray(dists).tolist(),
                          lengths.tolist()):
        if exclude is not None and t == exclude[0] and s < exclude[2] and s + n > exclude[1]:
            continue
        near = kept.setdefault(t, [])
        if any(abs(s - o) < radius for o in near):
            continue
        near.append(s)
        out.append((t, s, d))
        if len(out) >= k:
            break
    return out
