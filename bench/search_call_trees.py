#!/usr/bin/env python
"""The runtime search call of this tree against the same call at another git revision, whole trees
(the Python around the compiled filter included, which ``bench/search_tail.py --against`` keeps fixed).

Run-time queries are collected once (the motion matching controller on the built-in scenarios, numpy
search, as ``lmm-studio bench`` does) and pickled; each round then starts one process per tree, in
alternating order, that times the call the controller makes at a tick (tag groups in one pass, the
playing frame and its window, top 1 with the near frames) on every query and prints p50/p90/p99 and a
digest of the answers (frames, totals, biases: equal digests, equal answers). Prints each round, the
p50 ratio per round (this tree / REV) and its median; ``--json OUT`` writes them.

    python bench/search_call_trees.py REV [--rounds 5] [--queries 5000] [--db FILE.npz] [--json OUT]

REV is checked out into a temporary git worktree (removed afterwards); both trees use this venv.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def dump(out: str, n: int, db_path: str | None) -> None:
    """Collect ``n`` run-time queries with this tree and pickle what a runtime call needs."""
    sys.path.insert(0, str(ROOT))
    from app.commands.bench_runs import brute_force_args, collect_queries
    from lmm.data.build import load_or_build
    from lmm.data.database import Database
    from lmm.features import build_features
    from lmm.search import SearchIndex

    db = Database.load(db_path) if db_path else load_or_build()[0]
    orig = SearchIndex.update

    def numpy_only(self, features_norm):      # the numpy search's hints, as at run time without the filter
        rebuilt = orig(self, features_norm)
        self._native = False
        return rebuilt

    SearchIndex.update = numpy_only
    runs = collect_queries(db, build_features(db), n)
    SearchIndex.update = orig
    c0 = runs.queries[0][3]
    Path(out).write_bytes(pickle.dumps({"queries": [(q, f, h) for q, f, h, _ in runs.queries],
                                        "groups": c0.tag_groups(), "args": dict(brute_force_args(c0), top_k=1),
                                        "near": int(c0.tuning.top_k), "db": db_path}))


def time_tree(tree: str, queries: str) -> None:
    """Time the runtime call of the tree at ``tree`` on the pickled queries (run in a process of its own)."""
    sys.path.insert(0, tree)
    import numpy as np

    from lmm.data.build import load_or_build
    from lmm.data.database import Database
    from lmm.features import build_features
    from lmm.search import SearchIndex

    d = pickle.loads(Path(queries).read_bytes())
    db = Database.load(d["db"]) if d["db"] else load_or_build()[0]
    index = SearchIndex(build_features(db).normalized)
    groups, args, near = d["groups"], d["args"], d["near"]
    for q, f, hint in d["queries"][:200]:                      # warm up (the filter is built on first use)
        index.group_search(q, groups, current=f, hint=hint, near=near, **args)
    seconds, digest = [], hashlib.sha256()
    for q, f, hint in d["queries"]:
        t = time.perf_counter()
        r = index.group_search(q, groups, current=f, hint=hint, near=near, **args)
        seconds.append(time.perf_counter() - t)
        digest.update(r.frames.tobytes() + r.costs.tobytes() + r.bias.tobytes())
    us = np.asarray(seconds) * 1e6
    print(json.dumps({"compiled": bool(index._native), "digest": digest.hexdigest()[:16],
                      **{f"p{p}_us": float(np.percentile(us, p)) for p in (50, 90, 99)}}))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rev", help="the git revision to compare with")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--queries", type=int, default=5000)
    ap.add_argument("--db", help="database .npz (default: the default database)")
    ap.add_argument("--json", help="write the rounds and the median ratio here")
    ap.add_argument("--time-tree", nargs=2, metavar=("TREE", "QUERIES"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.time_tree:
        time_tree(*a.time_tree)
        return 0
    import numpy as np

    with tempfile.TemporaryDirectory(prefix="search-trees-") as tmp:
        other, queries = Path(tmp) / "tree", Path(tmp) / "queries.pkl"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "-q", "--detach", str(other), a.rev], check=True)
        try:
            dump(str(queries), a.queries, a.db)
            trees = {"this": str(ROOT), a.rev: str(other)}
            rounds = []
            for r in range(a.rounds):
                row = {}
                for name in (list(trees) if r % 2 == 0 else list(trees)[::-1]):
                    out = subprocess.run([sys.executable, __file__, a.rev, "--time-tree", trees[name], str(queries)],
                                         capture_output=True, text=True, check=True).stdout
                    row[name] = json.loads(out.strip().splitlines()[-1])
                row["p50_ratio"] = row["this"]["p50_us"] / row[a.rev]["p50_us"]
                row["same_answers"] = row["this"]["digest"] == row[a.rev]["digest"]
                rounds.append(row)
                print(f"round {r}: {a.rev} p50 {row[a.rev]['p50_us']:.1f} us, this tree {row['this']['p50_us']:.1f} us, "
                      f"ratio {row['p50_ratio']:.3f}, same answers {row['same_answers']}", flush=True)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(other)], check=False)
    result = {"rev": a.rev, "queries": a.queries, "db": a.db, "rounds": rounds,
              "median_p50_ratio": float(np.median([row["p50_ratio"] for row in rounds]))}
    print(f"median p50 ratio (this tree / {a.rev}): {result['median_p50_ratio']:.3f}")
    if a.json:
        Path(a.json).write_text(json.dumps(result, indent=1))
    return 0 if all(row["same_answers"] for row in rounds) else 1


if __name__ == "__main__":
    sys.exit(main())
