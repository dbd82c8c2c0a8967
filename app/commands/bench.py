"""``lmm-studio bench``: runtime benchmarks, one function per section, written as nested JSON.

    lmm-studio bench --json out/bench.json

Sections (later issues add theirs to ``SECTIONS``):

``search``  queries taken from real runs of every built-in scenario (at the searches the motion
            matching controller actually makes, with the default tuning); per query, the brute-force
            search and the accelerated exact search on the same query and controller state:
            ``frames`` (database size), ``queries``, ``bruteforce_us`` and ``accelerated_us``
            (medians per query), ``speedup`` (their ratio), ``agreement`` (fraction of queries with
            identical best frame and cost), ``topk_agreement`` (identical ordered top-K with costs).
            The brute force is :func:`lmm.search.brute_force_search`, whose cost pass is the fastest
            vectorised form found (``einsum``, about twice as fast as ``np.sum((X - q) ** 2, 1)``;
            both cost passes alone are reported too). Each search is timed in its own pass over the
            queries, as at run time: the brute force chunk by chunk while the queries are collected,
            right after the controllers' steps of the same chunk (so that the ``frame`` ratios to it
            compare the same minutes), the accelerated one afterwards, with the hint the controller
            gave it.
            ``runtime_call_us``: the call the controller makes at a tick (every tag group in one pass,
            the playing frame and its exclusion window, the best frame only, keeping the K frames of
            least cost it evaluated as the next hint, the hint), back to back;
            ``..._without_exclusion_us`` the same call without the playing frame; ``plain_query_us`` the
            plainest query (one mask, top-1, no playing frame, the hint), with the runtime call's ratios
            to both (issue 16's target: within 1.2x of the plain query); ``ranked_call_us``: the ranked
            top-K call the debugger's read of a tick's candidates makes. ``runtime_call_p50_us``,
            ``..._p90_us``, ``..._p99_us``: the runtime call's percentiles (with the compiled filter of
            :mod:`lmm.search_native` when ``runtime_call_compiled``), ``runtime_call_numpy_p*_us`` the
            same call through the numpy index alone (the fallback).
``frame``   ``mm_us``: median time of one motion matching controller step over the same runs;
            ``lmm_us``: median time of one learned controller step (shipped networks, debug
            comparison off) over the same inputs, stepped right after each 10 s chunk of motion
            matching steps, so both medians come from the same minutes of a machine whose speed
            drifts (with ``lmm_advance_us`` and ``lmm_projector_us``, its parts);
            ``mm_search_in_controller_us``: median time of the search as the controller makes it
            (exclusion window, tag groups, top-K, inside a tick, caches as other per-tick work left
            them), over the same runs, with ``..._over_bruteforce`` its ratio to ``search.bruteforce_us``;
            ``mm_over_bruteforce`` / ``lmm_over_bruteforce``: the frame times over the brute force
            (issue 16's target: at most 0.2); ``lmm_network_*_us`` with ``*_over_cpp``: each network per
            call on the inputs a run gave it, over a plain C++ evaluation of the same network on the
            same inputs (the reference demo's algorithm and release flags), built with the C++
            compiler found and timed in the same run (``lmm_network_cpp_source`` "measured"; without a
            compiler, "issue16": the figures the issue measured on another machine,
            ``CPP_NETWORK_US``); target at most 1.3.

Timings are wall-clock medians; every section also reports what it measured (counts, settings). How the
queries and steps are collected: :mod:`app.commands.bench_runs`; the sections: :mod:`app.commands.bench_sections`.
"""
from __future__ import annotations

import sys

from .bench_runs import collect_queries, learned_factory
from .bench_sections import bench_frame_with_lmm, bench_memory, bench_search


def add_arguments(p) -> None:
    p.add_argument("--json", dest="json_path", metavar="PATH", help="write the results here (nested JSON)")
    from app.cli import number_in

    # a query holds a feature vector and its masks (~300 bytes) and costs about 1 ms of searching per
    # pass: 100,000 take ~30 MB and a few minutes, more only makes the bench slower, not better
    p.add_argument("--queries", type=number_in(1, 100_000, integer=True), default=2400,
                   help="search queries to collect, 1..100000 (default 2400; >= 2000 for stable numbers)")
    p.add_argument("--sections", type=_sections, default="search,frame,memory",
                   help=f"comma-separated sections to run ({', '.join(SECTIONS)})")
    p.add_argument("--manifest", help="dataset manifest (default: the shipped LAFAN1 locomotion set)")


# name -> function(db, features, n_queries, collected) returning a dict; later issues add theirs
SECTIONS = {"search": bench_search, "frame": bench_frame_with_lmm, "memory": bench_memory}


def format_results(results: dict) -> str:
    lines = []
    for section, values in results.items():
        lines.append(f"[{section}]")
        width = max((len(k) for k in values), default=0)
        for k, v in values.items():
            text = f"{v:.4g}" if isinstance(v, float) else str(v)
            lines.append(f"  {k.ljust(width)}  {text}")
    return "\n".join(lines)


def _sections(text: str) -> list[str]:
    """``--sections``: known section names, comma-separated (an argparse type: a bad name exits 2)."""
    import argparse

    names = [s.strip() for s in text.split(",") if s.strip()]
    unknown = [s[:40] for s in names if s not in SECTIONS]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"unknown bench section(s) {', '.join(unknown) or '(none given)'} "
                                         f"(known: {', '.join(SECTIONS)})")
    return names


def main(args) -> int:
    names = args.sections if isinstance(args.sections, list) else _sections(args.sections)
    if args.json_path:
        from lmm.data.atomic import check_writable
        check_writable(args.json_path)  # before minutes of benchmarking

    from lmm.data.build import load_or_build
    from lmm.features import build_features

    db, _ = load_or_build(args.manifest)
    features = build_features(db)
    collected = None
    if {"search", "frame"} & set(names):
        print(f"collecting {args.queries} search queries from runs of the built-in scenarios...", file=sys.stderr)
        learned = learned_factory(db, features) if "frame" in names else None
        if learned is not None:
            print("  with the learned controller stepping the same inputs, interleaved", file=sys.stderr)
        collected = collect_queries(db, features, args.queries, learned=learned, brute="search" in names)
    results = {}
    for name in names:
        results[name] = SECTIONS[name](db, features, args.queries, collected)
    if "search" in results and "frame" in results:  # ratios within one run (the machine may be shared)
        brute = results["search"]["bruteforce_us"]
        frame = results["frame"]
        for key in ("mm_us", "lmm_us", "mm_search_in_controller_us"):
            if frame.get(key) is not None and brute > 0:
                frame[key.replace("_us", "_over_bruteforce")] = frame[key] / brute
        fast = results["search"]["accelerated_us"]
        if fast > 0 and frame.get("mm_search_in_controller_us") is not None:
            frame["mm_search_in_controller_over_accelerated"] = frame["mm_search_in_controller_us"] / fast
    print(format_results(results))
    if args.json_path:
        from lmm.data.jsonio import write_json
        write_json(args.json_path, results)
    return 0
