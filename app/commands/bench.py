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
            right after the controllers' steps of the same chunk (so that
            ``frame.mm_search_in_controller_over_bruteforce`` compares the same minutes), the
            accelerated one afterwards, with the hint the controller gave it.
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
            them), over the same runs, with ``..._over_bruteforce`` its ratio to ``search.bruteforce_us``.
            The C++ references, built with ``cpp_flags`` (the reference demo's own Makefile flags,
            ``-O3 -ffast-math -march=native``) by ``cpp_compiler``: ``lmm_network_*_us`` with
            ``*_cpp_us`` and ``*_over_cpp``: each network per call on the inputs a run gave it, against a
            plain C++ evaluation of the same network on the same inputs (the demo's algorithm;
            ``lmm_network_cpp_source``); whole frames (:mod:`app.commands.bench_frame_reference`;
            ``frame_reference.cpp`` says what a C++ frame includes): ``cpp_mm_frame_us`` and
            ``cpp_lmm_frame_us`` beside ours on the same inputs, ``mm_frame_us`` and ``lmm_frame_us``
            (median ticks, so the MM figures are of frames that did not search; ``..._frame_mean_us``
            the means, searches included; ``..._frame_searching_us`` the median tick that searched),
            in ``frame_rounds`` alternating rounds of ``frame_ticks`` ticks: medians over the rounds,
            ``mm_frame_over_cpp``, ``lmm_frame_over_cpp`` (and ``..._mean_over_cpp``,
            ``..._searching_over_cpp``) the medians of the rounds' ratios; the searches and jumps of
            each pass (``cpp_mm_frame_searches`` ...; a jump: the pose source jumped and an
            inertialization started) show both did the same work; ``cpp_frame_source`` "measured", or
            why not. Without a C++ compiler one note says so and the C++ figures are None.

The terminal gets a summary of the headline figures (:func:`format_summary`), ``--verbose`` every figure,
``--json PATH`` the whole nested JSON. Timings are wall-clock medians; every section also reports what it
measured (counts, settings). How the queries and steps are collected: :mod:`app.commands.bench_runs`; the
sections: :mod:`app.commands.bench_sections`.
"""
from __future__ import annotations

import sys

from .bench_runs import collect_queries, learned_factory
from .bench_sections import NETWORKS, bench_frame_with_lmm, bench_memory, bench_search


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
    p.add_argument("--frame-ticks", type=number_in(60, 36_000, integer=True), default=2400,
                   help="ticks per pass of the whole-frame comparison with the C++ reference, 60..36000 (default 2400)")
    p.add_argument("--frame-rounds", type=number_in(1, 50, integer=True), default=5,
                   help="alternating rounds of that comparison, 1..50 (default 5)")
    p.add_argument("--verbose", action="store_true",
                   help="print every figure (about 90 lines), not only the headline summary")


# name -> function(db, features, n_queries, collected) returning a dict; later issues add theirs
SECTIONS = {"search": bench_search, "frame": bench_frame_with_lmm, "memory": bench_memory}


def format_results(results: dict) -> str:
    """Every figure of every section, one per line (``--verbose``; about 90 lines for all sections)."""
    lines = []
    for section, values in results.items():
        lines.append(f"[{section}]")
        width = max((len(k) for k in values), default=0)
        for k, v in values.items():
            text = f"{v:.4g}" if isinstance(v, float) else str(v)
            lines.append(f"  {k.ljust(width)}  {text}")
    return "\n".join(lines)


def _num(v, unit: str = "") -> str:
    """A figure as the summary shows it: 4 significant digits and its unit, "n/a" when not measured."""
    if v is None or (isinstance(v, float) and v != v):
        return "n/a"
    return f"{v:.4g}{unit}"


def _megabytes(n) -> str:
    return "n/a" if n is None else f"{n / 1e6:.2f} MB"


def format_summary(results: dict) -> str:
    """The headline figures of the sections that ran, in at most about 20 lines (a terminal's worth):
    the search percentiles and brute force against accelerated, our whole frames against the C++
    reference's, the networks per call against C++, the memory of both controllers; then how many
    figures there are in all and where they are (``--verbose``, ``--json PATH``)."""
    lines = []
    s = results.get("search")
    if s is not None:
        lines += [f"[search] {s['frames']} frames, {s['queries']} queries; the same best frame in "
                  f"{s['agreement']:.1%}, the same top {s['top_k']} in {s['topk_agreement']:.1%}",
                  f"  brute force {_num(s['bruteforce_us'], ' us')}, accelerated {_num(s['accelerated_us'], ' us')}"
                  f" ({_num(s['speedup'], 'x')} faster)",
                  f"  runtime call p50 / p90 / p99: {_num(s['runtime_call_p50_us'])} / "
                  f"{_num(s['runtime_call_p90_us'])} / {_num(s['runtime_call_p99_us'], ' us')}"
                  f" ({'compiled filter' if s['runtime_call_compiled'] else 'numpy index'})",
                  f"  numpy index alone p50 / p90 / p99: {_num(s['runtime_call_numpy_p50_us'])} / "
                  f"{_num(s['runtime_call_numpy_p90_us'])} / {_num(s['runtime_call_numpy_p99_us'], ' us')}"]
    f = results.get("frame")
    if f is not None:
        lines += [f"[frame] controller step medians: MM {_num(f['mm_us'], ' us')} (its search "
                  f"{_num(f.get('mm_search_in_controller_us'), ' us')}), LMM {_num(f.get('lmm_us'), ' us')}"]
        if f.get("cpp_frame_source", "measured") == "measured" and "cpp_mm_frame_us" in f:
            lines.append(f"  whole frame, ours / C++ ({f['cpp_flags']}, {f['frame_rounds']} round(s) of "
                         f"{f['frame_ticks']} ticks):")
            for name in ("mm", "lmm"):
                lines.append(f"    {name.upper():3s} median {_num(f[f'{name}_frame_us'])} / "
                             f"{_num(f[f'cpp_{name}_frame_us'], ' us')} = {_num(f[f'{name}_frame_over_cpp'], 'x')},"
                             f" a tick that searched {_num(f[f'{name}_frame_searching_over_cpp'], 'x')},"
                             f" mean {_num(f[f'{name}_frame_mean_over_cpp'], 'x')}")
        elif "cpp_frame_source" in f:
            lines.append(f"  whole frame against C++: {f['cpp_frame_source']}")
        if f.get("lmm_network_cpp_source") == "measured":
            lines.append("  networks per call, ours / C++:")
            lines += [f"    {net:12s} {_num(f[f'lmm_network_{net}_us'])} / "
                      f"{_num(f[f'lmm_network_{net}_cpp_us'], ' us')}"
                      f" = {_num(f[f'lmm_network_{net}_over_cpp'], 'x')}" for net in NETWORKS]
        elif "lmm_network_cpp_source" in f:
            lines.append(f"  networks against C++: {f['lmm_network_cpp_source']}")
    m = results.get("memory")
    if m is not None:
        lines.append(f"[memory] MM {_megabytes(m['mm_bytes'])}, LMM {_megabytes(m['lmm_bytes'])}"
                     + (f" ({m['lmm_over_mm']:.3f} of MM)" if m.get("lmm_over_mm") is not None else ""))
    total = sum(len(v) for v in results.values())
    lines.append(f"({total} figures in all: --verbose prints them, --json PATH writes them)")
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
    if args.json_path:   # before minutes of benchmarking: never over an input, a device or a FIFO
        from app.commands.session_common import check_outputs
        from lmm.data.build import manifest_inputs
        check_outputs([("--json", args.json_path)], manifest_inputs(args.manifest))

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
    options = {"frame": {"frame_ticks": args.frame_ticks, "frame_rounds": args.frame_rounds}}
    for name in names:
        results[name] = SECTIONS[name](db, features, args.queries, collected, **options.get(name, {}))
    if "search" in results and "frame" in results:  # ratios within one run (the machine may be shared)
        brute = results["search"]["bruteforce_us"]
        frame = results["frame"]
        if frame.get("mm_search_in_controller_us") is not None and brute > 0:
            frame["mm_search_in_controller_over_bruteforce"] = frame["mm_search_in_controller_us"] / brute
        fast = results["search"]["accelerated_us"]
        if fast > 0 and frame.get("mm_search_in_controller_us") is not None:
            frame["mm_search_in_controller_over_accelerated"] = frame["mm_search_in_controller_us"] / fast
    print(format_results(results) if args.verbose else format_summary(results))
    if args.json_path:
        from lmm.data.jsonio import write_json
        write_json(args.json_path, results)
    return 0
