"""Headless runs: a controller driven by an input source for a number of seconds, with metrics.

Deterministic: the same controller state, input and tick produce the same poses, so a recording made
from the same input is byte-identical on the same machine (timings are measured but never recorded).
"""
from __future__ import annotations

import time

from lmm.metrics import MotionMetrics


def run_headless(controller, input_source, seconds: float, dt: float = 1.0 / 60.0, recorder=None, on_step=None,
                 input_writer=None, realtime: bool = False, reset: bool = True) -> dict:
    """Step ``controller`` for ``seconds`` at ``dt`` and return its metrics (see :mod:`lmm.metrics`).

    ``input_source(t) -> InputState`` (an :class:`lmm.data.inputs.InputLog` works); ``recorder.write(pose)``
    and ``input_writer.write(t, input)`` stream the run; ``on_step(pose, snapshot)`` sees every tick.
    ``realtime`` paces the ticks to the wall clock (for interactive recordings and crash tests).
    """
    if dt <= 0:
        raise ValueError(f"dt must be positive, got {dt}")
    if reset:
        controller.reset()
    metrics = MotionMetrics(controller.db)
    n_ticks = int(round(seconds / dt))
    start = time.perf_counter()
    for i in range(n_ticks):
        t = i * dt
        inp = input_source(t)
        if input_writer is not None:
            input_writer.write(t, inp)
        pose, snap = controller.step(inp, dt)
        if recorder is not None:
            recorder.write(pose)
        metrics.update(snap)
        if on_step is not None:
            on_step(pose, snap)
        if realtime:
            wait = start + (i + 1) * dt - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
    result = metrics.result()
    result["wall_s"] = time.perf_counter() - start
    return result
