"""Evaluation of motion search by example: the learned encoder, the classifier baseline and the plain
features baseline side by side, on a folder of takes (default: the 27 shared LAFAN1 takes), numpy only.

Searched: every window (every resampled frame's start) of every take, embedded by each method and
searched by exact Euclidean k-NN (:func:`lmm.motion_search.embed.knn`). Queries: ``queries_per_take``
windows evenly spaced in each take's held-out part (:mod:`lmm.offline.search_data`; the networks never
trained on these frames, but the searched database holds them, as a user's database would).

* ``precision@k``: the fraction of the first ``k`` results whose take has the query's action label,
  after dropping the results that overlap the query itself (same take, starts less than a window apart);
  ``precision@5_other_takes``: the same with every result from the query's own take dropped, over the
  queries whose label has another take (a harder number: it asks for the same action by someone else).
* ``recall@5_warp0.8`` / ``recall@5_warp1.25`` / ``recall@5_mirror``: the fraction of queries played at
  0.8x / 1.25x speed (:func:`lmm.offline.search_data.warped_segments`) or mirrored whose source window
  (same take, start within ``tolerance`` frames) is among the first 5 results; ``recall@5_plain`` is the
  same for the query as cut (a sanity check).
* ``latency_ms``: the median time to embed one query window and search the whole database (k = 10).

On another folder the shipped networks (trained on LAFAN1) have seen none of it; to train on it too:
``python -m lmm.offline.search_training --data DIR --out NETS`` and ``--encoder``/``--classifier`` from NETS.
"""
from __future__ import annotations

import hashlib
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from lmm.motion_search import windows as W
from lmm.motion_search.embed import FeatureEmbedder, knn
from lmm.offline import search_data as data

METHODS = ("encoder", "classifier", "features")


@dataclass
class EvalSettings:
    queries_per_take: int = 24
    warps: tuple[float, ...] = (0.8, 1.25)
    tolerance: int = 15            # resampled (30 fps) frames
    latency_queries: int = 50
    search_k: int = 200            # neighbours fetched before the overlapping ones are dropped


@dataclass
class Database:
    """Every window of every take: the take index and resampled start of each row."""
    takes: list[data.Take]
    take_of: np.ndarray
    start_of: np.ndarray

    @classmethod
    def of(cls, takes: list[data.Take]) -> "Database":
        ids = [np.full(t.n_windows, i, np.int64) for i, t in enumerate(takes)]
        starts = [np.arange(t.n_windows, dtype=np.int64) for t in takes]
        return cls(takes, np.concatenate(ids) if ids else np.zeros(0, np.int64),
                   np.concatenate(starts) if starts else np.zeros(0, np.int64))

    def embed(self, embedder, chunk: int = 8192) -> np.ndarray:
        out = []
        for t in self.takes:
            w = W.windows(t.frames)
            for s in range(0, len(w), chunk):
                out.append(embedder.embed(w[s:s + chunk]))
        return np.concatenate(out).astype(np.float32) if out else np.zeros((0, 1), np.float32)


def query_starts(take: data.Take, n: int, max_speed: float) -> np.ndarray:
    """Up to ``n`` evenly spaced starts inside the held-out part with room for the fastest query."""
    last = len(take.frames) - 1 - int(np.ceil((W.WINDOW_FRAMES - 1) * max_speed))
    first = take.held_out_start
    if last < first:
        return np.zeros(0, np.int64)
    return np.unique(np.linspace(first, last, n).round().astype(np.int64))


def cached_embeddings(db: Database, embedder, key: str, log=None) -> tuple[np.ndarray, float]:
    """The database's embeddings by ``embedder``, from the cache folder when present; (vectors, seconds
    spent embedding, 0 when cached)."""
    from lmm.data.atomic import atomic_write
    from lmm.data.cache import default_cache_dir

    path = default_cache_dir() / "search" / f"emb-{key}.npy"
    if path.is_file():
        try:
            e = np.load(path, allow_pickle=False)
            if e.shape[0] == len(db.take_of):
                return e, 0.0
        except Exception:  # noqa: BLE001 - a damaged cache is rebuilt
            pass
    if log:
        log(f"embedding {len(db.take_of)} windows with {embedder.name}")
    t0 = time.perf_counter()
    e = db.embed(embedder)
    seconds = time.perf_counter() - t0
    with atomic_write(path) as f:
        np.save(f, e)
    return e, seconds


def _hits_source(idx, db: Database, take: int, start: int, tol: int) -> bool:
    return bool(np.any((db.take_of[idx] == take) & (np.abs(db.start_of[idx] - start) <= tol)))


def evaluate_method(embedder, db: Database, vectors: np.ndarray, queries: list[tuple[int, int]],
                    settings: EvalSettings) -> dict:
    takes = db.takes
    labels = np.array([t.label for t in takes])
    label_takes = {lab: int(np.sum(labels == lab)) for lab in set(labels)}
    qt = np.array([q[0] for q in queries])
    qs = np.array([q[1] for q in queries])
    plain = np.stack([W.windows(takes[t].frames)[s] for t, s in queries])
    idx, _ = knn(vectors, embedder.embed(plain), settings.search_k)
    prec = {1: [], 5: [], 10: []}
    other, by_label = [], {}
    for row, t, s in zip(idx, qt, qs):
        same = db.take_of[row] == t
        keep = row[~(same & (np.abs(db.start_of[row] - s) < W.WINDOW_FRAMES))]
        rel = labels[db.take_of[keep]] == labels[t]
        for k in prec:
            prec[k].append(float(np.mean(rel[:k])) if len(rel) >= k else float(np.mean(rel)) if len(rel) else 0.0)
        by_label.setdefault(labels[t], []).append(prec[5][-1])
        if label_takes[labels[t]] > 1:
            rest = row[~same]
            other.append(float(np.mean(labels[db.take_of[rest[:5]]] == labels[t])) if len(rest) else 0.0)
    out = {f"precision@{k}": float(np.mean(v)) for k, v in prec.items()}
    out["precision@5_other_takes"] = float(np.mean(other)) if other else None
    out["precision@5_by_label"] = {lab: float(np.mean(v)) for lab, v in sorted(by_label.items())}
    variants = {"plain": plain, "mirror": W.mirror_frames(plain)}
    for speed in settings.warps:
        variants[f"warp{speed:g}"] = np.stack([data.warped_segments(takes[t].frames, [s], [speed])[0]
                                               for t, s in queries])
    for name, x in variants.items():
        top, _ = knn(vectors, embedder.embed(x), 5)
        out[f"recall@5_{name}"] = float(np.mean([_hits_source(r, db, t, s, settings.tolerance)
                                                 for r, t, s in zip(top, qt, qs)]))
    times = []
    for i in range(min(settings.latency_queries, len(plain))):
        t0 = time.perf_counter()
        knn(vectors, embedder.embed(plain[i:i + 1]), 10)
        times.append(time.perf_counter() - t0)
    out["latency_ms"] = float(np.median(times) * 1e3) if times else None
    out["dim"] = int(vectors.shape[1])
    return out


def load_embedders(takes: list[data.Take], encoder_path=None, classifier_path=None) -> dict:
    """The three methods: the encoder and classifier from their files (default: the shipped ones), the
    features baseline scaled by the training frames' spreads."""
    from lmm.motion_search import encoder as enc

    return {"encoder": enc.load(encoder_path or enc.DEFAULT_WEIGHTS),
            "classifier": enc.load(classifier_path or enc.CLASSIFIER_WEIGHTS),
            "features": FeatureEmbedder().fit(np.concatenate(data.training_frames(takes)))}


def evaluate(folder=None, encoder_path=None, classifier_path=None, settings: EvalSettings | None = None,
             log=None) -> dict:
    """The evaluation report (see the module doc) as a JSON-ready dict."""
    settings = settings or EvalSettings()
    folder = Path(folder) if folder is not None else data.DEFAULT_DATA_DIR
    takes = data.load_takes(folder, log=log)
    embedders = load_embedders(takes, encoder_path, classifier_path)
    db = Database.of(takes)
    if not len(db.take_of):
        raise data.SearchDataError(f"{folder}: no take is longer than one window ({W.WINDOW_FRAMES} frames at "
                                   f"{W.WINDOW_FPS:g} fps)")
    queries = [(i, int(s)) for i, t in enumerate(takes)
               for s in query_starts(t, settings.queries_per_take, max(settings.warps + (1.0,)))]
    if not queries:
        raise data.SearchDataError(f"{folder}: no take has a held-out part long enough for a query")
    frames_key = data.folder_key(folder, data.bvh_files(folder))
    report = {"data": str(folder), "n_takes": len(takes), "n_windows": int(len(db.take_of)),
              "n_queries": len(queries),
              "labels": {lab: sum(t.label == lab for t in takes) for lab in data.labels_of(takes)},
              "split": f"queries from the last {data.HELD_OUT_FRACTION:.0%} of each take; training on the frames "
                       f"before it; the searched database holds every window",
              "settings": asdict(settings), "methods": {}}
    for name, emb in embedders.items():
        extra = emb.scale.tobytes() if name == "features" else b""
        key = hashlib.sha256(f"{frames_key}|{emb.name}|".encode() + extra).hexdigest()[:24]
        vectors, build_s = cached_embeddings(db, emb, key, log)
        if log:
            log(f"evaluating {name}")
        r = evaluate_method(emb, db, vectors, queries, settings)
        r["database_embed_s"] = round(build_s, 2) if build_s else "cached"
        report["methods"][name] = r
    return report


COLUMNS = ("precision@1", "precision@5", "precision@10", "precision@5_other_takes", "recall@5_warp0.8",
           "recall@5_warp1.25", "recall@5_mirror", "recall@5_plain", "latency_ms", "dim")


def format_table(report: dict) -> str:
    """The methods side by side, one row each (markdown)."""
    short = [c.replace("precision", "P").replace("recall", "R").replace("_other_takes", " other") for c in COLUMNS]
    lines = ["| method | " + " | ".join(short) + " |", "|---" * (len(COLUMNS) + 1) + "|"]
    for name, r in report["methods"].items():
        cells = []
        for c in COLUMNS:
            v = r.get(c)
            cells.append("-" if v is None else f"{v:.0f}" if c == "dim" else f"{v:.1f}" if c == "latency_ms"
                         else f"{v:.3f}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
