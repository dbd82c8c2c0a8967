"""The one tick loop: every controller stepped with the same input, and headless runs built on it.

:func:`step_controllers` is one tick for a set of controllers; ``lmm-studio run`` (:func:`run_headless`),
the evaluation's MM vs LMM runs (:mod:`lmm.offline.evaluation`) and the studio session
(:class:`app.session.Session`) all step through it, so a tick means the same everywhere.

Deterministic: the same controller state, input and tick produce the same poses, so a recording made
from the same input is byte-identical on the same machine (timings are measured but never recorded).
"""
from __future__ import annotations

import time

from lmm.controller import Controller, DebugSnapshot, InputState, Pose
from lmm.metrics import MotionMetrics


def step_controllers(controllers: dict[str, Controller], inp: InputState, dt: float
                     ) -> tuple[dict[str, Pose], dict[str, DebugSnapshot], dict[str, float]]:
    """One tick of ``dt`` seconds: step each controller (in the dict's order) with the same input.

    Returns ``(poses, snapshots, ms)`` keyed like ``controllers``; ``ms`` is each step's wall time in
    milliseconds. Controllers share nothing but the input, so the order never changes a result.
    """
    poses, snaps, ms = {}, {}, {}
    for name, controller in controllers.items():
        t0 = time.perf_counter()
        poses[name], snaps[name] = controller.step(inp, dt)
        ms[name] = (time.perf_counter() - t0) * 1e3
    return poses, snaps, ms


def run_headless(controller, input_source, seconds: float, dt: float = 1.0 / 60.0, recorder=None, on_step=None,
                 input_writer=None, realtime: bool = False, reset: bool = True, before_step=None,
                 after_step=None) -> dict:
    """Step ``controller`` for ``seconds`` at ``dt`` and return its metrics (see :mod:`lmm.metrics`).

    ``input_source(t) -> InputState`` (an :class:`lmm.data.inputs.InputLog` works); ``recorder.write(pose)``
    and ``input_writer.write(t, input)`` stream the run; ``on_step(pose, snapshot)`` sees every tick.
    ``realtime`` paces the ticks to the wall clock (for interactive recordings and crash tests).
    ``before_step(i, input)`` runs before tick ``i`` is stepped (a session's events act there) and
    ``after_step(i, poses)`` after it (a session writer's fingerprints and commits, :mod:`lmm.session`).
    """
    if dt <= 0:
        raise ValueError(f"dt must be positive, got {dt}")
    if reset:
        controller.reset()
    controllers = {controller.name: controller}
    metrics = MotionMetrics(controller.db)
    n_ticks = int(round(seconds / dt))
    start = time.perf_counter()
    for i in range(n_ticks):
        t = i * dt
        inp = input_source(t)
        if input_writer is not None:
            input_writer.write(t, inp)
        if before_step is not None:
            before_step(i, inp)
        poses, snaps, _ = step_controllers(controllers, inp, dt)
        pose, snap = poses[controller.name], snaps[controller.name]
        usable = metrics.update(snap)      # a non-finite or runaway pose is counted, never recorded
        if recorder is not None and usable:
            recorder.write(pose)
        if after_step is not None:
            after_step(i, poses)
        if on_step is not None:
            on_step(pose, snap)
        if realtime:
            wait = start + (i + 1) * dt - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
    result = metrics.result()
    if metrics.first_bad_tick is not None:
        result["first_non_finite_tick"] = metrics.first_bad_tick
        result["first_non_finite_problem"] = metrics.first_bad_problem
    result["wall_s"] = time.perf_counter() - start
    return result
