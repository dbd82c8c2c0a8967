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
            top-K call the debugger's read of a tick's candidates makes.
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

Timings are wall-clock medians; every section also reports what it measured (counts, settings).
"""
from __future__ import annotations

import sys
import time


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


class Runs:
    """What :func:`collect_queries` gathered: the search queries with the state they were made in, every
    motion matching step's time and every in-controller search's time, and, when a learned controller was
    stepped beside it, that controller's :class:`LearnedRuns`."""

    def __init__(self, queries, step_us, search_us, learned=None, brute=None):
        self.queries, self.step_us, self.search_us, self.learned = queries, step_us, search_us, learned
        self.brute = brute      # per query (brute-force result, seconds), or None


class LearnedRuns:
    """The learned controller's steps over the same inputs as the motion matching runs, interleaved with
    them chunk by chunk: step times (us), each step's ``advance`` part, the projector's time on the steps
    that projected, the networks' real inputs (states, and queries in the networks' space) and the
    networks."""

    def __init__(self):
        self.step_us, self.advance_us, self.projector_us, self.states, self.queries = [], [], [], [], []
        self.nets = None


def collect_queries(db, features, n_queries: int, scenarios=None, tuning=None, learned=None,
                    brute: bool = False) -> Runs:
    """Run the MM controller on every built-in scenario in turn (round robin, 10 s at a time) until
    ``n_queries`` searches have been made.

    ``learned``: a function making a learned controller (see :func:`learned_factory`). One per scenario
    then steps the same inputs right after each motion matching chunk; with ``brute`` each chunk's
    queries are then searched by brute force (:func:`lmm.search.brute_force_search`, timed, one pass
    over the chunk's queries). So the step times and the brute-force times, whose ratios issue 16 sets
    targets on, are medians over the same minutes of a machine whose speed changes from minute to
    minute."""
    import numpy as np

    from lmm.data.inputs import builtin, builtin_names
    from lmm.mm import MotionMatchingController
    from lmm.runner import step_controllers
    from lmm.tuning import Tuning

    scenarios = scenarios or builtin_names((1, 2))
    chunk_s, dt = 10.0, 1.0 / 60.0
    chunk = int(chunk_s / dt)
    controllers, learners, logs, ticks = {}, {}, {}, {}
    queries, step_us, search_us, brute_runs = [], [], [], [] if brute else None
    lr = LearnedRuns() if learned is not None else None
    while len(queries) < n_queries:
        for name in scenarios:
            if name not in controllers:
                c = MotionMatchingController(db, features, tuning.copy() if tuning else Tuning())
                c.search_log = []
                controllers[name], ticks[name] = c, 0
                logs[name] = builtin(name, 3600.0)
                if lr is not None:
                    learners[name] = learned()
                    learners[name].reset()
            c, log, start = controllers[name], logs[name], ticks[name]
            for i in range(start, start + chunk):
                _, snaps, ms = step_controllers({name: c}, log.at(i * dt), dt)
                step_us.append(ms[name] * 1e3)
                if snaps[name].searched:
                    search_us.append(snaps[name].timings_us["search"])
            ticks[name] = start + chunk
            new = [(query, frame, hint, c) for query, frame, hint in c.search_log]
            queries += new
            c.search_log.clear()
            if lr is not None:
                _step_learned(learners[name], log, start, chunk, dt, lr)
            if brute_runs is not None:
                brute_runs += _time_brute_force(new)
    return Runs(queries[:n_queries], np.asarray(step_us), np.asarray(search_us), lr,
                None if brute_runs is None else brute_runs[:n_queries])


def brute_force_args(controller) -> dict:
    """The search arguments a benchmark query is searched with: the controller's, from its tuning (the
    playing frame is given per query)."""
    args = controller.search_args(int(controller.tuning.top_k))
    del args["current"]
    return args


def _time_brute_force(queries) -> list:
    """(result, seconds) of the brute-force search of each of ``queries`` (query, frame, hint, controller)."""
    from lmm.search import brute_force_search

    out = []
    for query, frame, _, c in queries:
        X, mask, args = c.features.normalized, c.candidate_mask(), brute_force_args(c)
        t0 = time.perf_counter()
        r = brute_force_search(X, query, mask, current=frame, **args)
        out.append((r, time.perf_counter() - t0))
    return out


def _step_learned(controller, log, start: int, count: int, dt: float, into: LearnedRuns) -> None:
    """Step a learned controller over ticks ``start .. start + count`` of ``log``, into ``into``."""
    from lmm.runner import step_controllers

    nets = into.nets = controller.nets
    for i in range(start, start + count):
        _, snaps, ms = step_controllers({"lmm": controller}, log.at(i * dt), dt)
        snap = snaps["lmm"]
        into.step_us.append(ms["lmm"] * 1e3)
        into.advance_us.append(snap.timings_us.get("advance", float("nan")))
        if len(into.states) < 2000:
            into.states.append(controller.state.copy())
        if "projector" in snap.timings_us:
            into.projector_us.append(snap.timings_us["projector"])
            if len(into.queries) < 2000:
                into.queries.append(nets.to_network_space(controller.features.denormalize(snap.query)))


def bench_search(db, features, n_queries: int = 2400, collected=None) -> dict:
    import numpy as np

    from lmm.search import SearchIndex

    runs = collected or collect_queries(db, features, n_queries, brute=True)
    queries = runs.queries
    c0 = queries[0][3]
    args = brute_force_args(c0)
    mask = c0.candidate_mask()
    X = c0.features.normalized
    index = SearchIndex(X)
    # each search timed on its own pass over the queries (as at run time, not interleaved with the other):
    # the brute force chunk by chunk while they were collected (see collect_queries), else here
    if runs.brute is None:
        runs.brute = _time_brute_force(queries)
    brute = [r for r, _ in runs.brute]
    t_brute = [t for _, t in runs.brute]
    fast, t_fast = [], []
    for query, frame, hint, _ in queries:
        t0 = time.perf_counter()
        r = index.search(query, mask, current=frame, hint=hint, **args)
        t_fast.append(time.perf_counter() - t0)
        fast.append(r)
    # the runtime call as the controller makes it at a tick (tag groups in one pass, the playing frame, its
    # exclusion window, the best frame only with the near frames kept as the next hint, the hint) against
    # plain queries on the same index: the same call without the playing frame and its window, and the
    # plainest query (one mask, top-1, no playing frame); and the ranked top K the debugger reads
    groups = c0.tag_groups()
    top1 = dict(args, top_k=1)
    t_run, t_free, t_plain, t_ranked = [], [], [], []
    for query, frame, hint, _ in queries:
        t0 = time.perf_counter()
        index.group_search(query, groups, current=frame, hint=hint, near=args["top_k"], **top1)
        t1 = time.perf_counter()
        index.group_search(query, groups, current=-1, hint=hint, near=args["top_k"], **top1)
        t2 = time.perf_counter()
        index.search(query, mask, hint=hint)
        t3 = time.perf_counter()
        index.group_search(query, groups, current=frame, hint=hint, **args)
        t4 = time.perf_counter()
        t_run.append(t1 - t0)
        t_free.append(t2 - t1)
        t_plain.append(t3 - t2)
        t_ranked.append(t4 - t3)
    run_us, free_us, plain_us, ranked_us = (float(np.median(t) * 1e6) for t in (t_run, t_free, t_plain, t_ranked))
    same_best = [a.best_frame == b.best_frame and a.best_cost == b.best_cost for a, b in zip(brute, fast)]
    same_topk = [np.array_equal(a.frames, b.frames) and np.array_equal(a.costs, b.costs)
                 and np.array_equal(a.channel_costs, b.channel_costs) for a, b in zip(brute, fast)]
    bru, acc = float(np.median(t_brute) * 1e6), float(np.median(t_fast) * 1e6)
    return {
        "frames": int(X.shape[0]),
        "dims": int(X.shape[1]),
        "queries": len(queries),
        "top_k": int(args["top_k"]),
        "bruteforce_us": bru,
        "accelerated_us": acc,
        "speedup": bru / acc if acc > 0 else float("nan"),
        "agreement": float(np.mean(same_best)),
        "topk_agreement": float(np.mean(same_topk)),
        "accelerated_p90_us": float(np.percentile(t_fast, 90) * 1e6),
        "bruteforce_p90_us": float(np.percentile(t_brute, 90) * 1e6),
        "frames_evaluated_median": float(np.median([r.evaluated for r in fast])),
        "runtime_call_us": run_us,
        "runtime_call_without_exclusion_us": free_us,
        "plain_query_us": plain_us,
        "runtime_call_over_without_exclusion": run_us / free_us if free_us > 0 else float("nan"),
        "runtime_call_over_plain_query": run_us / plain_us if plain_us > 0 else float("nan"),
        "ranked_call_us": ranked_us,
        # context for the brute-force figure: the cost pass alone, as the reference computes it
        # (einsum) and as the textbook numpy expression np.sum((X - q) ** 2, axis=1) does
        **_cost_pass_us(X, [q for q, *_ in queries[:300]]),
    }


def _cost_pass_us(X, queries) -> dict:
    import numpy as np

    t_einsum, t_sum = [], []
    for q in queries:
        t0 = time.perf_counter()
        d = X - q
        np.einsum("ij,ij->i", d, d)
        t1 = time.perf_counter()
        np.sum((X - q) ** 2, axis=1)
        t2 = time.perf_counter()
        t_einsum.append(t1 - t0)
        t_sum.append(t2 - t1)
    return {"cost_pass_einsum_us": float(np.median(t_einsum) * 1e6),
            "cost_pass_textbook_us": float(np.median(t_sum) * 1e6)}


def bench_frame(db, features, n_queries: int = 2400, collected=None) -> dict:
    import numpy as np

    runs = collected or collect_queries(db, features, n_queries)
    step_us, search_us = runs.step_us, runs.search_us
    return {"mm_us": float(np.median(step_us)), "mm_p90_us": float(np.percentile(step_us, 90)),
            "mm_steps": int(step_us.size),
            "mm_search_in_controller_us": float(np.median(search_us)) if search_us.size else float("nan"),
            "mm_searches": int(search_us.size)}


#: Per-call times (us) of the C++ reference demo's networks (``nnet.h``, -O3) on our weights, as issue 16
#: measured them on its machine: ``bench`` uses them only when it cannot build and run the same-run C++
#: reference (:mod:`app.commands.cpp_reference`), and says so (``lmm_network_cpp_source``).
CPP_NETWORK_US = {"decompressor": 8.5, "stepper": 12.1, "projector": 17.3}


# name -> function(db, features, n_queries, collected) returning a dict; later issues append theirs
SECTIONS = {"search": bench_search, "frame": bench_frame}


# -- learned motion matching (issue 4): frame.lmm_us and the paper's Table 3 memory figures ----------

def learned_factory(db, features):
    """A function making learned controllers with the shipped networks (loaded once, shared) as the
    benchmarks run them: debug nearest-neighbour comparison off. None, with a note, when the shipped
    networks do not fit this database."""
    cached = getattr(learned_factory, "cache", None)
    if cached is not None and cached[0] is db and cached[1] is features:
        return cached[2]
    from lmm.data.weights import WeightsError
    from lmm.learned import LearnedMotionMatchingController, load_default_networks

    try:
        nets = load_default_networks(db, features)
    except WeightsError as e:
        print(f"note: no learned-controller figures ({e})", file=sys.stderr)
        make = None
    else:
        def make():
            return LearnedMotionMatchingController(db, features, networks=nets, compare_with_search=False)
    learned_factory.cache = (db, features, make)
    return make


def memory_figures(db, features, controllers: dict) -> dict:
    """``memory.*``: what each controller's :meth:`lmm.controller.Controller.memory_bytes` reports (the
    numbers the studio's stats panel shows), MM after one tick so its search index exists."""
    from lmm.controller import InputState

    mm = controllers["mm"]
    mm.reset()
    mm.step(InputState(), 1.0 / 60.0)        # the first tick searches: the index is built
    parts = mm.memory_bytes()
    mm_total = int(sum(parts.values()))
    out = {"memory.mm_bytes": mm_total, "memory.mm_features_bytes": parts["features (X)"],
           "memory.mm_pose_bytes": parts["pose data (Y)"], "memory.mm_search_bytes": parts["search index"],
           "memory.lmm_bytes": None}
    if "lmm" in controllers:
        lmm_total = int(sum(controllers["lmm"].memory_bytes().values()))
        out["memory.lmm_bytes"] = lmm_total
        out["memory.lmm_over_mm"] = float(lmm_total / max(mm_total, 1))
    return out


def benchmark_lmm(runs: LearnedRuns) -> dict:
    """``frame.lmm_us`` (median learned-controller step, debug comparison off, through the one tick loop
    :func:`lmm.runner.step_controllers`, over the same inputs as the motion matching steps and
    interleaved with them: see :func:`collect_queries`), its advance and projector parts, and the
    networks alone at batch 1 (``network.*_us``, as in the paper's table) on the inputs the runs gave
    them, with the C++ reference's times on the same inputs (``network.*_cpp_us``, see
    :mod:`app.commands.cpp_reference`)."""
    import numpy as np

    nets = runs.nets
    states = np.array(runs.states, np.float32)
    queries = runs.queries or [np.zeros(nets.projector.n_in, np.float32)]
    samples = {"decompressor": states, "stepper": states, "projector": np.array(queries, np.float32)}

    def median_us(net, xs, n=2000):
        out = np.empty(net.n_out, np.float32)
        for x in xs:                   # one pass over the inputs first, as the C++ reference does
            net(x, out)
        ts = []
        for k in range(n):
            x = xs[k % len(xs)]
            t0 = time.perf_counter()
            net(x, out)
            ts.append((time.perf_counter() - t0) * 1e6)
        return float(np.median(ts))

    figures = {
        "frame.lmm_us": float(np.median(runs.step_us)),
        "frame.lmm_p90_us": float(np.percentile(runs.step_us, 90)),
        "frame.lmm_steps": len(runs.step_us),
        "frame.lmm_advance_us": float(np.nanmedian(runs.advance_us)),
        "frame.lmm_projector_us": float(np.median(runs.projector_us)) if runs.projector_us else float("nan"),
    }
    figures.update({f"network.{name}_us": median_us(getattr(nets, name), xs) for name, xs in samples.items()})
    from app.commands import cpp_reference
    from lmm.data.cache import default_cache_dir

    cpp, why = cpp_reference.measure({name: getattr(nets, name) for name in samples}, samples, default_cache_dir())
    if cpp is None:
        print(f"note: C++ network reference not measured here ({why}); using issue 16's figures", file=sys.stderr)
    figures["network.cpp_source"] = "measured" if cpp is not None else "issue16"
    figures.update({f"network.{name}_cpp_us": (cpp or CPP_NETWORK_US)[name] for name in samples})
    return figures


def _memory(db, features) -> dict:
    """The memory figures of both controllers (computed once per run)."""
    cached = getattr(_memory, "cache", None)
    if cached is not None and cached[0] is db:
        return cached[1]
    from lmm.mm import MotionMatchingController

    controllers = {"mm": MotionMatchingController(db, features)}
    make = learned_factory(db, features)
    if make is not None:
        controllers["lmm"] = make()
    figures = memory_figures(db, features, controllers)
    _memory.cache = (db, figures)
    return figures


def bench_frame_with_lmm(db, features, n_queries: int = 2400, collected=None) -> dict:
    """``frame``: the motion matching step (above) plus ``lmm_us``, the median learned-controller step
    (shipped networks, debug nearest-neighbour comparison off) over the same inputs, interleaved with
    the motion matching steps, and its parts; None without networks for this database."""
    make = learned_factory(db, features)
    runs = collected or collect_queries(db, features, n_queries, learned=make)
    out = bench_frame(db, features, n_queries, runs)
    if runs.learned is None or not runs.learned.step_us:
        out["lmm_us"] = None
        return out
    fig = benchmark_lmm(runs.learned)
    out.update({k.split(".", 1)[1]: v for k, v in fig.items() if k.startswith("frame.")})
    out.update({k.replace("network.", "lmm_network_"): v for k, v in fig.items() if k.startswith("network.")})
    for net in CPP_NETWORK_US:
        ours, cpp = out.get(f"lmm_network_{net}_us"), out.get(f"lmm_network_{net}_cpp_us")
        out[f"lmm_network_{net}_over_cpp"] = ours / cpp if ours is not None and cpp else None
    return out


def bench_memory(db, features, n_queries: int = 2400, collected=None) -> dict:
    """``memory``: ``mm_bytes`` (features + pose database + search structure at run time) and
    ``lmm_bytes`` (decompressor + stepper + projector), as in the paper's Table 3."""
    fig = _memory(db, features)
    return {k.split(".", 1)[1]: v for k, v in fig.items() if k.startswith("memory.")}


SECTIONS["frame"] = bench_frame_with_lmm
SECTIONS["memory"] = bench_memory


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
