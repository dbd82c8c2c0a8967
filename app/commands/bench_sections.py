"""The sections of ``lmm-studio bench`` (see :mod:`app.commands.bench` for what each reports): the
search, the frame (motion matching and learned motion matching steps, the networks and whole frames
against the C++ reference) and the memory figures."""
from __future__ import annotations

import sys
import time

from .bench_runs import LearnedRuns, brute_force_args, collect_queries, learned_factory, time_brute_force


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
        runs.brute = time_brute_force(queries)
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
    # plainest query (one mask, top-1, no playing frame); and the ranked top K the debugger reads; the
    # runtime call also through the numpy index alone (no compiled filter: the fallback's figures)
    groups = c0.tag_groups()
    top1 = dict(args, top_k=1)
    numpy_index = SearchIndex(X)
    numpy_index._native = False
    t_run, t_free, t_plain, t_ranked, t_numpy = [], [], [], [], []
    for query, frame, hint, _ in queries:
        t0 = time.perf_counter()
        index.group_search(query, groups, current=frame, hint=hint, near=args["top_k"], **top1)
        t_run.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        numpy_index.group_search(query, groups, current=frame, hint=hint, near=args["top_k"], **top1)
        t_numpy.append(time.perf_counter() - t0)
        t1 = time.perf_counter()
        index.group_search(query, groups, current=-1, hint=hint, near=args["top_k"], **top1)
        t2 = time.perf_counter()
        index.search(query, mask, hint=hint)
        t3 = time.perf_counter()
        index.group_search(query, groups, current=frame, hint=hint, **args)
        t4 = time.perf_counter()
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
        # the runtime call's tail, with the compiled filter when it runs (lmm.search_native) and with numpy alone
        "runtime_call_compiled": bool(index._native),
        **_percentiles_us("runtime_call", t_run),
        **_percentiles_us("runtime_call_numpy", t_numpy),
        # context for the brute-force figure: the cost pass alone, as the reference computes it
        # (einsum) and as the textbook numpy expression np.sum((X - q) ** 2, axis=1) does
        **_cost_pass_us(X, [q for q, *_ in queries[:300]]),
    }


def _percentiles_us(name: str, seconds) -> dict:
    """``NAME_p50_us``, ``NAME_p90_us`` and ``NAME_p99_us`` of the times."""
    import numpy as np

    return {f"{name}_p{p}_us": float(np.percentile(seconds, p) * 1e6) for p in (50, 90, 99)}


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


#: the learned controller's runtime networks, as the bench names them
NETWORKS = ("decompressor", "stepper", "projector")


# -- learned motion matching (issue 4): frame.lmm_us and the paper's Table 3 memory figures ----------

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
        lmm_parts = controllers["lmm"].memory_bytes()
        lmm_total = int(sum(lmm_parts.values()))
        out["memory.lmm_bytes"] = lmm_total
        out.update({f"memory.lmm_{name}_bytes": int(v) for name, v in lmm_parts.items()})   # what each keeps
        out["memory.lmm_over_mm"] = float(lmm_total / max(mm_total, 1))
    return out


def benchmark_lmm(runs: LearnedRuns, cpp: bool = True) -> dict:
    """``frame.lmm_us`` (median learned-controller step, debug comparison off, through the one tick loop
    :func:`lmm.runner.step_controllers`, over the same inputs as the motion matching steps and
    interleaved with them: see :func:`collect_queries`), its advance and projector parts, and the
    networks alone at batch 1 (``network.*_us``, as in the paper's table) on the inputs the runs gave
    them, with the C++ reference's times on the same inputs (``network.*_cpp_us``, see
    :mod:`app.commands.cpp_reference`; None without ``cpp`` or when it cannot be measured)."""
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

    cpp_us, why = None, "no C++ compiler"
    if cpp:
        cpp_us, why = cpp_reference.measure({name: getattr(nets, name) for name in samples}, samples,
                                            default_cache_dir())
        if cpp_us is None:
            print(f"note: C++ network reference not measured ({why})", file=sys.stderr)
    figures["network.cpp_source"] = "measured" if cpp_us is not None else f"not measured: {why}"
    figures.update({f"network.{name}_cpp_us": None if cpp_us is None else cpp_us[name] for name in samples})
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


def bench_frame_with_lmm(db, features, n_queries: int = 2400, collected=None, frame_ticks: int = 2400,
                         frame_rounds: int = 5) -> dict:
    """``frame``: the motion matching step (above) plus ``lmm_us``, the median learned-controller step
    (shipped networks, debug nearest-neighbour comparison off) over the same inputs, interleaved with
    the motion matching steps, and its parts; None without networks for this database. Then the C++
    references, built with ``cpp_flags``: the networks per call, and whole frames beside ours
    (:mod:`app.commands.bench_frame_reference`); without a C++ compiler one note says so and their
    figures are None."""
    from app.commands import cpp_reference

    make = learned_factory(db, features)
    runs = collected or collect_queries(db, features, n_queries, learned=make)
    out = bench_frame(db, features, n_queries, runs)
    if runs.learned is None or not runs.learned.step_us:
        out["lmm_us"] = None
        return out
    cxx = cpp_reference.compiler()
    if cxx is None:
        print("note: no C++ reference figures: no C++ compiler ($CXX, or g++, clang++ or c++ on PATH)",
              file=sys.stderr)
    fig = benchmark_lmm(runs.learned, cpp=cxx is not None)
    out.update({k.split(".", 1)[1]: v for k, v in fig.items() if k.startswith("frame.")})
    out.update({k.replace("network.", "lmm_network_"): v for k, v in fig.items() if k.startswith("network.")})
    for net in NETWORKS:
        ours, cpp = out.get(f"lmm_network_{net}_us"), out.get(f"lmm_network_{net}_cpp_us")
        out[f"lmm_network_{net}_over_cpp"] = ours / cpp if ours is not None and cpp else None
    out["cpp_flags"] = " ".join(cpp_reference.FLAGS)
    out["cpp_compiler"] = cxx
    out.update(whole_frames(db, features, make, cxx is not None, frame_ticks, frame_rounds))
    return out


def whole_frames(db, features, make_learned, cpp: bool, ticks: int = 2400, rounds: int = 5) -> dict:
    """Whole frames, ours and the C++ reference's, on the same inputs in alternating rounds (see
    :func:`app.commands.bench_frame_reference.measure_frames`): ``cpp_mm_frame_us``,
    ``cpp_lmm_frame_us``, ``mm_frame_us``, ``lmm_frame_us`` (median ticks; ``..._frame_mean_us`` the
    means, searches included), their ``..._over_cpp`` ratios, searches and jumps per pass, and
    ``cpp_frame_source``. Without ``cpp`` (or when the reference cannot run) only the source, saying why."""
    from app.commands.bench_frame_reference import frame_inputs, measure_frames
    from lmm.data.cache import default_cache_dir
    from lmm.mm import MotionMatchingController

    fig, why = None, "no C++ compiler"
    if cpp:
        fig, why = measure_frames(MotionMatchingController(db, features), make_learned(), frame_inputs(ticks),
                                  default_cache_dir(), rounds)
        if fig is None:
            print(f"note: C++ frame reference not measured ({why})", file=sys.stderr)
    keys = ("cpp_mm_frame_us", "cpp_lmm_frame_us", "mm_frame_us", "lmm_frame_us")
    out = {"cpp_frame_source": "measured" if fig is not None else f"not measured: {why}"}
    out.update(fig if fig is not None else {k: None for k in keys})
    return out


def bench_memory(db, features, n_queries: int = 2400, collected=None) -> dict:
    """``memory``: ``mm_bytes`` (features + pose database + search structure at run time) and
    ``lmm_bytes`` (decompressor + stepper + projector, each as ``lmm_NAME_bytes``), as in the paper's
    Table 3."""
    fig = _memory(db, features)
    return {k.split(".", 1)[1]: v for k, v in fig.items() if k.startswith("memory.")}
