#!/usr/bin/env python
"""Benchmark of the foundations: BVH parse throughput, database build (cold and cached), features.

Prints a table and, with --json PATH, writes the numbers. Timings are medians of --repeat runs;
compare numbers within one run (the machine is noisy).

    python bench/bench_database.py [--repeat 3] [--json out.json]
"""
from __future__ import annotations

import argparse
import gzip
import json
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lmm import DEFAULT_MANIFEST
from lmm.data import bvh  # noqa: E402
from lmm.data.build import load_or_build  # noqa: E402
from lmm.features import build_features  # noqa: E402
from lmm.data.manifest import load_manifest  # noqa: E402
from bench_bvh import median_time  # noqa: E402  (same folder)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args()

    manifest = load_manifest(DEFAULT_MANIFEST)
    parse = []
    for clip in manifest.clips:
        text_bytes = len(gzip.open(clip.file).read()) if clip.file.suffix == ".gz" else clip.file.stat().st_size
        t = median_time(lambda: bvh.load(clip.file), args.repeat)
        parse.append({"file": clip.file.name, "mb": text_bytes / 1e6, "seconds": t, "mb_per_s": text_bytes / 1e6 / t})
    total_mb = sum(p["mb"] for p in parse)
    total_s = sum(p["seconds"] for p in parse)

    cold, cached = [], []
    for _ in range(args.repeat):
        with tempfile.TemporaryDirectory() as cache:
            db, info = load_or_build(cache_dir=cache)
            assert not info.cached
            cold.append(info.seconds)
            _, info2 = load_or_build(cache_dir=cache)
            assert info2.cached
            cached.append(info2.seconds)
    t_feat = median_time(lambda: build_features(db), args.repeat)

    result = {
        "bvh": {"files": parse, "total_mb": total_mb, "total_seconds": total_s, "mb_per_s": total_mb / total_s},
        "database": {
            "build_cold_s": statistics.median(cold), "build_cached_s": statistics.median(cached),
            "frames": db.n_frames, "seconds_of_motion": db.seconds, "ranges": db.n_ranges, "bones": db.n_bones,
            "pose_bytes": db.pose_bytes(), "cache_file_bytes": None,
        },
        "features": {"build_s": t_feat, "dims": 27},
    }
    with tempfile.TemporaryDirectory() as cache:
        _, info = load_or_build(cache_dir=cache)
        result["database"]["cache_file_bytes"] = info.path.stat().st_size

    print(f"BVH parse (.bvh.gz, median of {args.repeat})")
    for p in parse:
        print(f"  {p['file']:<36} {p['mb']:6.2f} MB  {p['seconds'] * 1000:7.1f} ms  {p['mb_per_s']:6.1f} MB/s")
    print(f"  {'all':<36} {total_mb:6.2f} MB  {total_s * 1000:7.1f} ms  {total_mb / total_s:6.1f} MB/s")
    d = result["database"]
    print(f"database build  cold {d['build_cold_s']:.2f} s   cached {d['build_cached_s'] * 1000:.0f} ms")
    print(f"database size   {d['frames']} frames ({d['seconds_of_motion']:.0f} s at 60 fps), {d['ranges']} ranges, "
          f"{d['pose_bytes'] / 2**20:.1f} MiB pose data, cache file {d['cache_file_bytes'] / 2**20:.1f} MiB")
    print(f"features build  {t_feat:.2f} s")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
