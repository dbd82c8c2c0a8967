#!/usr/bin/env python
"""Benchmark of lmm.data.bvh: parse and save times for the LAFAN1 takes.

For every shipped take (lmm/data/lafan1/*.bvh.gz) and its uncompressed original
(../shared/data/lafan1/*.bvh, when present) prints the median of N runs of
``bvh.load`` and the throughput in MB/s of BVH text, then the median time of
``bvh.save`` to .bvh and to .bvh.gz.

    python bench/bench_bvh.py [--repeat 5] [--all-originals] [--pybvh] [--json out.json]
"""
from __future__ import annotations

import argparse
import gzip
import json
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lmm.data import bvh  # noqa: E402

SHIPPED_DIR = ROOT / "lmm" / "data" / "lafan1"
ORIGINALS_DIR = ROOT.parent / "shared" / "data" / "lafan1"


def median_time(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=5, help="runs per measurement (median reported)")
    ap.add_argument("--all-originals", action="store_true",
                    help="parse every .bvh in the originals folder, not only the shipped takes' originals")
    ap.add_argument("--pybvh", action="store_true", help="also time pybvh.read_bvh_file on the .bvh files")
    ap.add_argument("--json", metavar="PATH", help="write the results as JSON")
    args = ap.parse_args(argv)

    shipped = sorted(SHIPPED_DIR.glob("*.bvh.gz"))
    if args.all_originals:
        originals = sorted(ORIGINALS_DIR.glob("*.bvh"))
    else:
        originals = [ORIGINALS_DIR / p.name[:-3] for p in shipped]
        originals = [p for p in originals if p.exists()]
    if not shipped and not originals:
        print("no takes found", file=sys.stderr)
        return 1

    results = {"python": sys.version.split()[0], "machine": platform.machine(), "repeat": args.repeat,
               "parse": [], "save": []}
    print(f"{'file':44s} {'MB':>6s} {'frames':>7s} {'load s':>8s} {'MB/s':>7s}" + ("  pybvh s" if args.pybvh else ""))
    for path in shipped + originals:
        raw = path.read_bytes()
        text_bytes = len(gzip.decompress(raw)) if raw[:2] == b"\x1f\x8b" else len(raw)
        anim = bvh.load(path)
        t = median_time(lambda: bvh.load(path), args.repeat)
        row = {"file": str(path), "compressed": path.name.endswith(".gz"), "bytes_on_disk": len(raw),
               "text_bytes": text_bytes, "frames": anim.n_frames, "channels": anim.n_channels,
               "load_s": t, "mb_per_s": text_bytes / 1e6 / t}
        line = f"{path.name:44s} {text_bytes / 1e6:6.2f} {anim.n_frames:7d} {t:8.4f} {text_bytes / 1e6 / t:7.1f}"
        if args.pybvh and not path.name.endswith(".gz"):
            import pybvh
            row["pybvh_load_s"] = median_time(lambda: pybvh.read_bvh_file(path, world_up="+y"), args.repeat)
            line += f"  {row['pybvh_load_s']:7.4f}"
        print(line)
        results["parse"].append(row)

    if shipped:
        print(f"\n{'save':44s} {'.bvh s':>8s} {'.bvh.gz s':>10s}")
        with tempfile.TemporaryDirectory() as tmp:
            for path in shipped:
                anim = bvh.load(path)
                t_txt = median_time(lambda: bvh.save(Path(tmp) / "out.bvh", anim), args.repeat)
                t_gz = median_time(lambda: bvh.save(Path(tmp) / "out.bvh.gz", anim), args.repeat)
                print(f"{path.name:44s} {t_txt:8.4f} {t_gz:10.4f}")
                results["save"].append({"file": str(path), "frames": anim.n_frames, "save_bvh_s": t_txt,
                                        "save_bvh_gz_s": t_gz})

    loads = [r["load_s"] for r in results["parse"]]
    mbps = [r["mb_per_s"] for r in results["parse"]]
    print(f"\nload: median {statistics.median(loads):.4f} s per take, max {max(loads):.4f} s, "
          f"median {statistics.median(mbps):.1f} MB/s")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
