"""A/B: a session replayed as recorded (arm A) and with another tuning from a tick on (arm B), in lockstep.

Both arms step the same recorded input and actions; arm B takes the preset's fields at ``from_tick`` on top
of the tuning then, and not the recorded tuning changes after it (:class:`lmm.session.player.SessionPlayer`).
Per tick and controller: the pose difference (mean and largest joint distance between the arms, metres),
each arm's played-pose cost and transitions. Arm A must reproduce the recording (its fingerprints are
checked); before ``from_tick`` the arms are identical, so the difference there must be 0.
"""
from __future__ import annotations

import numpy as np

from lmm.metrics import MotionMetrics


def compare(session, db, features, branch: dict, from_tick: int, weights=None) -> tuple[dict, dict]:
    """``(report, series)``: the JSON-ready report (both arms' :mod:`lmm.metrics`, per-controller pose
    difference summary, arm A's fingerprint check) and per-tick series for plotting."""
    from lmm.session.player import SessionPlayer

    a = SessionPlayer(session, db, features, weights=weights)
    b = SessionPlayer(session, db, features, branch=branch, from_tick=from_tick, weights=weights)
    names = list(a.controllers)
    n = session.ticks
    metrics = {arm: {name: MotionMetrics(db) for name in names} for arm in ("a", "b")}
    mean_d = {name: np.zeros(n) for name in names}
    max_d = {name: np.zeros(n) for name in names}
    cost = {arm: {name: np.full(n, np.nan) for name in names} for arm in ("a", "b")}
    transitions = {arm: {name: np.zeros(n, np.int64) for name in names} for arm in ("a", "b")}
    while not a.done:
        tick = a.tick
        poses_a, snaps_a = a.step()
        poses_b, snaps_b = b.step()
        for name in names:
            d = np.linalg.norm(poses_a[name].global_positions.astype(np.float64)
                               - poses_b[name].global_positions.astype(np.float64), axis=-1)
            mean_d[name][tick], max_d[name][tick] = float(d.mean()), float(d.max())
            for arm, snaps in (("a", snaps_a), ("b", snaps_b)):
                metrics[arm][name].update(snaps[name])
                cost[arm][name][tick] = float(snaps[name].current_cost)
                transitions[arm][name][tick] = int(bool(snaps[name].transitioned))
    report = {"session": str(session.path), "ticks": n, "fps": session.fps, "from_tick": int(from_tick),
              "from_time_s": from_tick * session.dt,
              "arm_a": {"fingerprints_checked": a.checked, "fingerprints_differing": len(a.mismatches),
                        "first_differing": list(a.mismatches[0]) if a.mismatches else None},
              "controllers": {}}
    for name in names:
        before, after = max_d[name][:from_tick], max_d[name][from_tick:]
        differing = np.flatnonzero(max_d[name] > 0.0)
        report["controllers"][name] = {
            "a": metrics["a"][name].result(), "b": metrics["b"][name].result(),
            "pose_difference_m": {
                "before_branch_max": float(before.max()) if before.size else 0.0,
                "after_branch_mean": float(mean_d[name][from_tick:].mean()) if after.size else 0.0,
                "after_branch_max": float(after.max()) if after.size else 0.0,
                "first_differing_tick": int(differing[0]) if differing.size else None,
                "differing_ticks": int(differing.size)},
            "transitions_after_branch": {arm: int(transitions[arm][name][from_tick:].sum()) for arm in ("a", "b")},
        }
    series = {"time_s": (np.arange(n) + 1) * session.dt, "mean_difference_m": mean_d, "max_difference_m": max_d,
              "cost": cost, "transitions": transitions}
    return report, series


def _log10(values: np.ndarray) -> np.ndarray:
    """log10 of positive costs (NaN, a gap in the plot, elsewhere)."""
    out = np.full(values.shape, np.nan)
    positive = values > 0
    out[positive] = np.log10(values[positive])
    return out


def plot(series: dict, report: dict, out_dir) -> list[str]:
    """One PNG per controller in ``out_dir``: pose difference, each arm's played-pose cost and cumulative
    transitions over time, the branch tick marked (:func:`lmm.reporting.draw_lines_png`)."""
    from pathlib import Path

    from lmm.reporting import draw_lines_png

    out = []
    t = series["time_s"]
    for name in series["mean_difference_m"]:
        panels = [
            ("pose difference between the arms (m)", "s",
             {"mean joint": (t, series["mean_difference_m"][name]), "largest joint": (t, series["max_difference_m"][name])}),
            ("played pose's cost against the query (log10: rare spikes after sharp input changes)", "s",
             {"A": (t, _log10(series["cost"]["a"][name])), "B": (t, _log10(series["cost"]["b"][name]))}),
            ("transitions so far", "s",
             {"A": (t, np.cumsum(series["transitions"]["a"][name])), "B": (t, np.cumsum(series["transitions"]["b"][name]))}),
        ]
        path = Path(out_dir) / f"ab_{name}.png"
        draw_lines_png(panels, path, title=f"{name}: A as recorded vs B from tick {report['from_tick']} "
                                           f"({report['from_time_s']:g} s, dashed)",
                       marker_x=report["from_time_s"])
        out.append(str(path))
    return out
