#!/usr/bin/env python
"""Benchmark of motion search by example: index build (cold and cached) and query latency.

Over every .bvh under a folder (default: the 27 shared LAFAN1 takes, ../shared/data/lafan1; users: any
folder), it builds the index in a fresh cache folder (cold: read, reduce and embed every window), loads it
again (cached), then times --queries queries (file ranges of 32 to 96 frames cut at random, time-warped
and noisy like a user's example) end to end in one process: embedding, exact k-NN, suppression and DTW
re-ranking. Also the parts: k-NN in numpy vs faiss-cpu's exact flat index (when installed), DTW in numpy
vs dtaidistance (when installed), and `lmm-studio find` as a new process on the cached index. Prints a
table; --json OUT writes the numbers. Medians; the machine is shared, compare numbers within one run.

    python bench/find_latency.py [DIR] [--queries 30] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from lmm.motion_search import index as I  # noqa: E402
from lmm.motion_search.dtw import dtw_distances, have_dtaidistance  # noqa: E402

# ../shared/data/lafan1 beside the checkout (or beside a folder holding it: git worktrees)
DEFAULT_DIR = next((p / "shared" / "data" / "lafan1" for p in ROOT.parents if (p / "shared" / "data" / "lafan1").is_dir()),
                   ROOT.parent / "shared" / "data" / "lafan1")


def median_ms(fn, calls) -> float:
    times = []
    for c in calls:
        t = time.perf_counter()
        fn(c)
        times.append(time.perf_counter() - t)
    return 1000.0 * statistics.median(times)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", nargs="?", default=str(DEFAULT_DIR))
    ap.add_argument("--queries", type=int, default=30)
    ap.add_argument("--top", type=int, default=10)
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args()

    sources = I.sources_from(args.folder)
    out: dict = {"folder": args.folder, "files": len(sources), "queries": args.queries}
    with tempfile.TemporaryDirectory() as cache:
        t = time.perf_counter()
        index = I.MotionIndex.build(sources, cache_dir=cache)
        out["build_cold_s"] = time.perf_counter() - t
        out["cache_mib"] = index.cache_path.stat().st_size / 2**20 if index.cache_path.exists() else 0.0
        t = time.perf_counter()
        index = I.MotionIndex.build(sources, cache_dir=cache)
        out["build_cached_s"] = time.perf_counter() - t
        assert index.from_cache
        out["windows"] = index.n_windows
        out["embedder"] = index.embedder.name
        out["dim"] = int(index.embeddings.shape[1])

        rng = np.random.default_rng(0)
        queries = []
        for _ in range(args.queries):
            t = int(rng.integers(len(sources)))
            frames = index.take(t)
            n = int(rng.integers(32, 97))
            a = int(rng.integers(0, len(frames) - 2 * n))
            warp = float(rng.uniform(0.8, 1.25))
            src = frames[a:a + n]
            q = I.resample_length(src, max(8, int(round(n * warp))))
            queries.append(q + rng.normal(scale=0.02, size=q.shape).astype(np.float32) * index.scale)
        for q in queries[:3]:
            index.search(q, top=args.top)  # warm up (first matrix products, norms)
        out["query_ms"] = median_ms(lambda q: index.search(q, top=args.top), queries)
        out["query_dtw_numpy_ms"] = median_ms(lambda q: index.search(q, top=args.top, dtw_backend="numpy"), queries)
        out["query_no_rerank_ms"] = median_ms(lambda q: index.search(q, top=args.top, rerank=0), queries)

        # the parts: k-NN of one query window (200 nearest) and DTW of 150 candidate segments
        vectors = [index.embeddings[int(i)][None] + 0.01 for i in rng.integers(0, index.n_windows, args.queries)]
        index.nearest_windows(vectors[0], 200)
        out["knn_numpy_ms"] = median_ms(lambda v: index.nearest_windows(v, 200), vectors)
        try:
            import faiss

            flat = faiss.IndexFlatL2(index.embeddings.shape[1])
            flat.add(index.embeddings)
            flat.search(vectors[0], 200)
            out["knn_faiss_ms"] = median_ms(lambda v: flat.search(v, 200), vectors)
        except ImportError:
            out["knn_faiss_ms"] = None
        q = queries[0][:32] / index.scale
        segs = np.stack([index.frames[s:s + 40] for s in rng.integers(0, len(index.frames) - 40, 150)]) / index.scale
        out["dtw150_numpy_ms"] = median_ms(lambda _: dtw_distances(q, segs, 5, "numpy"), range(10))
        out["dtw150_dtaidistance_ms"] = (median_ms(lambda _: dtw_distances(q, segs, 5, "dtaidistance"), range(10))
                                         if have_dtaidistance() else None)

        # a new process per query, on the cached index (what a user of `lmm-studio find` waits)
        env_cache = Path(cache).parent / (Path(cache).name + "-cli")
        first = sources[0]
        cmd = [sys.executable, "-m", "app.cli", "find", str(first.path), "--frames", "100:160", "--in",
               args.folder, "--quiet"]
        import os

        env = dict(os.environ, LMM_STUDIO_CACHE=str(env_cache), PYTHONPATH=str(ROOT))
        subprocess.run(cmd, env=env, capture_output=True, check=True, cwd=ROOT)  # builds the CLI's cache
        walls = []
        for _ in range(5):
            t = time.perf_counter()
            subprocess.run(cmd, env=env, capture_output=True, check=True, cwd=ROOT)
            walls.append(time.perf_counter() - t)
        out["cli_cached_wall_ms"] = 1000.0 * statistics.median(walls)
        import shutil

        shutil.rmtree(env_cache, ignore_errors=True)

    rows = [
        ("files / windows", f"{out['files']} / {out['windows']} ({out['embedder']}, {out['dim']}-D)"),
        ("index build, cold", f"{out['build_cold_s']:.2f} s ({out['cache_mib']:.0f} MiB cache file)"),
        ("index load, cached", f"{out['build_cached_s']:.2f} s"),
        (f"query (median of {args.queries})", f"{out['query_ms']:.1f} ms (k-NN + DTW re-rank of {I.RERANK_TOP})"),
        ("  with numpy DTW", f"{out['query_dtw_numpy_ms']:.1f} ms"),
        ("  without re-ranking", f"{out['query_no_rerank_ms']:.1f} ms"),
        ("k-NN 200 of 1, numpy", f"{out['knn_numpy_ms']:.1f} ms"),
        ("k-NN 200 of 1, faiss flat", "not installed" if out["knn_faiss_ms"] is None else f"{out['knn_faiss_ms']:.1f} ms"),
        ("DTW 32 x 40 x 150, numpy", f"{out['dtw150_numpy_ms']:.1f} ms"),
        ("DTW 32 x 40 x 150, dtaidistance", "not installed" if out["dtw150_dtaidistance_ms"] is None
         else f"{out['dtw150_dtaidistance_ms']:.1f} ms"),
        ("lmm-studio find, cached (new process)", f"{out['cli_cached_wall_ms']:.0f} ms wall"),
    ]
    width = max(len(r[0]) for r in rows)
    for name, value in rows:
        print(f"{name:<{width}}  {value}")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
