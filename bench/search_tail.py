#!/usr/bin/env python
"""The runtime search call's latency, with and without the compiled filter (lmm/native/search.c), and its
agreement with the brute force.

The motion matching controller runs the built-in scenarios (round robin, as ``lmm-studio bench`` does) on
a database until --queries searches were made, with the numpy search (so each logged hint is the one the
numpy index is given at run time; the compiled filter reads none). Each query is then searched as the
controller searches it at a tick (its tag groups in one pass, the playing frame and its window, top 1 with
the near frames) by the numpy index and by the compiled filter, in alternating chunks of 1,000 queries, on
two indexes of the same features, each --repeats times; the first --brute queries also by the brute force.
Prints p50/p90/p99 per path (us) of the first calls and of each query's least call (on a shared machine a
preempted call takes milliseconds whatever it computes), and the agreements (same frames, totals and
biases); --json OUT writes them.

    python bench/search_tail.py [--db FILE.npz] [--queries 10000] [--brute 10000] [--json out.json]
                                [--against REV [--rounds 5]]

--against REV also times the compiled filter as it was at git revision REV (its lmm/search_native.py and
lmm/native/search.c, built into the cache folder like this tree's) against this tree's, on the same queries
in alternating chunks of 500, --rounds times (the first path swapped each round): each round's p50/p90/p99
of both and their p50 ratio, and the median over the rounds (a shared machine's speed changes from minute
to minute; the ratio within a round does not).

Without --db: the default database (the shipped locomotion set). The full LAFAN1 set:
``LAFAN1_DIR=/path/to/lafan1 lmm-studio build-db --manifest lmm/data/manifests/lafan1_full.json --out full.npz``.
"""
from __future__ import annotations

import argparse
import importlib.util
import inspect
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from app.commands.bench_runs import brute_force_args, collect_queries  # noqa: E402
from lmm import search_native  # noqa: E402
from lmm.data.build import load_or_build  # noqa: E402
from lmm.data.database import Database  # noqa: E402
from lmm.features import build_features  # noqa: E402
from lmm.search import SearchIndex, biased_search, brute_force_search  # noqa: E402


def percentiles(seconds) -> dict:
    us = np.asarray(seconds) * 1e6
    return {f"p{p}_us": float(np.percentile(us, p)) for p in (50, 90, 99)} | {"max_us": float(us.max())}


def same(a, b) -> bool:
    return np.array_equal(a.frames, b.frames) and np.array_equal(a.costs, b.costs) and np.array_equal(a.bias, b.bias)


def filter_at(rev: str):
    """:mod:`lmm.search_native` as it was at git revision ``rev`` (a module of its own, with that revision's
    C source beside it)."""
    folder = Path(tempfile.mkdtemp(prefix="search_native-"))
    (folder / "native").mkdir()
    for path, out in (("lmm/search_native.py", folder / "search_native.py"),
                      ("lmm/native/search.c", folder / "native" / "search.c")):
        out.write_bytes(subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{path}"], capture_output=True,
                                       check=True).stdout)
    spec = importlib.util.spec_from_file_location("search_native_at_rev", folder / "search_native.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def against(rev, X, queries, groups, near, args, rounds) -> dict:
    """Runtime-call times with REV's compiled filter and this tree's, alternating (see the module's doc)."""
    old = filter_at(rev)
    indexes = {"against": SearchIndex(X), "this": SearchIndex(X)}
    indexes["against"]._native = old.group_filter(indexes["against"])
    indexes["this"]._native = search_native.group_filter(indexes["this"])
    assert indexes["against"]._native and indexes["this"]._native, "both compiled filters load"
    tick = getattr(indexes["against"]._native, "tick", None)
    if tick is None or "wlo" not in inspect.signature(tick).parameters:
        # before 5074663 the filter's interface and the Python around it were different, and until the filter
        # took the exclusion window and ranked a top-1 search itself the Python around it was: compare whole trees
        raise SystemExit(f"--against {rev}: its filter predates this tree's interface; "
                         f"use python bench/search_call_trees.py {rev}")
    per_round = []
    for r in range(rounds):
        times = {name: [] for name in indexes}
        order = list(indexes) if r % 2 == 0 else list(indexes)[::-1]
        for start in range(0, len(queries), 500):
            for name in order:
                index = indexes[name]
                for query, frame, hint, _ in queries[start:start + 500]:
                    t = time.perf_counter()
                    index.group_search(query, groups, current=frame, hint=hint, near=near, **args)
                    times[name].append(time.perf_counter() - t)
        row = {name: percentiles(t) for name, t in times.items()}
        row["p50_ratio"] = row["this"]["p50_us"] / row["against"]["p50_us"]
        per_round.append(row)
        print(f"round {r}: {rev} p50 {row['against']['p50_us']:.1f} us, this tree {row['this']['p50_us']:.1f} us, "
              f"ratio {row['p50_ratio']:.3f}", file=sys.stderr, flush=True)
    med = {name: {key: float(np.median([row[name][key] for row in per_round])) for key in per_round[0][name]}
           for name in indexes}
    return {"rev": rev, "rounds": per_round, "median_over_rounds": med,
            "median_p50_ratio": float(np.median([row["p50_ratio"] for row in per_round]))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--db", help="database .npz (default: the default database)")
    ap.add_argument("--queries", type=int, default=10000)
    ap.add_argument("--brute", type=int, default=None, help="queries checked by brute force (default: all)")
    ap.add_argument("--repeats", type=int, default=3,
                    help="calls per query: the first call's times, and the least of them (a shared machine's "
                         "preemptions removed), are reported")
    ap.add_argument("--json", help="write the figures here")
    ap.add_argument("--against", metavar="REV", help="also time REV's compiled filter against this tree's")
    ap.add_argument("--rounds", type=int, default=5, help="alternating rounds of --against")
    a = ap.parse_args(argv)
    db = Database.load(a.db) if a.db else load_or_build()[0]
    features = build_features(db)
    if search_native.library() is None:
        print(f"no compiled search: {search_native.note() or 'switched off'}", file=sys.stderr)
        return 1
    # the queries, made with the numpy search (the runtime hints of the numpy index)
    orig = SearchIndex.update

    def numpy_only(self, features_norm):
        rebuilt = orig(self, features_norm)
        self._native = False
        return rebuilt

    SearchIndex.update = numpy_only
    t0 = time.perf_counter()
    runs = collect_queries(db, features, a.queries)
    SearchIndex.update = orig
    queries = runs.queries
    print(f"{len(queries)} queries on {db.n_frames} frames in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    c0 = queries[0][3]
    args = dict(brute_force_args(c0), top_k=1)
    near = int(c0.tuning.top_k)
    groups = c0.tag_groups()
    X = c0.features.normalized
    numpy_index, compiled = SearchIndex(X), SearchIndex(X)
    numpy_index._native = False
    times = {"numpy": [], "compiled": []}
    least = {"numpy": [], "compiled": []}     # per query, the least of --repeats calls
    results = {"numpy": [], "compiled": []}
    for start in range(0, len(queries), 1000):
        for name, index in (("numpy", numpy_index), ("compiled", compiled)):
            for query, frame, hint, _ in queries[start:start + 1000]:
                calls = []
                for _ in range(a.repeats):
                    t = time.perf_counter()
                    r = index.group_search(query, groups, current=frame, hint=hint, near=near, **args)
                    calls.append(time.perf_counter() - t)
                times[name].append(calls[0])
                least[name].append(min(calls))
                results[name].append(r)
    assert compiled._native, "the compiled filter ran"
    print(json.dumps({name: percentiles(t) for name, t in times.items()}), file=sys.stderr, flush=True)
    n_brute = len(queries) if a.brute is None else min(a.brute, len(queries))
    brute_same = []
    for (query, frame, _, _), fast in zip(queries[:n_brute], results["compiled"]):
        ref = biased_search(lambda **kw: brute_force_search(X, query, **kw), groups[0][1], None, group_masks=groups,
                            current=frame, **args)
        brute_same.append(same(fast, ref))
    out = {"frames": int(db.n_frames), "queries": len(queries),
           "numpy": percentiles(times["numpy"]), "compiled": percentiles(times["compiled"]),
           "repeats": a.repeats, "numpy_least_of_repeats": percentiles(least["numpy"]),
           "compiled_least_of_repeats": percentiles(least["compiled"]),
           "agreement_compiled_numpy": float(np.mean([same(x, y) for x, y in zip(results["compiled"],
                                                                                 results["numpy"])])),
           "brute_force_checked": n_brute,
           "agreement_compiled_brute_force": float(np.mean(brute_same)) if brute_same else float("nan")}
    if a.against:
        out["against"] = against(a.against, X, queries, groups, near, args, a.rounds)
    print(json.dumps(out, indent=1))
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
