"""How ``lmm-studio bench`` runs the controllers: the search queries motion matching makes in every
built-in scenario, with the state they were made in and each step's time, the brute-force search timed
chunk by chunk as it goes, and the learned controller stepping the same inputs, interleaved."""
from __future__ import annotations

import sys
import time


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
    over the chunk's queries). So the step times and the brute-force times are medians over the same
    minutes of a machine whose speed changes from minute to minute."""
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
                brute_runs += time_brute_force(new)
    return Runs(queries[:n_queries], np.asarray(step_us), np.asarray(search_us), lr,
                None if brute_runs is None else brute_runs[:n_queries])


def brute_force_args(controller) -> dict:
    """The search arguments a benchmark query is searched with: the controller's, from its tuning (the
    playing frame is given per query)."""
    args = controller.search_args(int(controller.tuning.top_k))
    del args["current"]
    return args


def time_brute_force(queries) -> list:
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
