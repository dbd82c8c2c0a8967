"""Motion quality and cost metrics, accumulated from per-tick debug snapshots (streaming, O(1) memory).

* foot skating (:class:`FootSkating`, the one definition, also used by ``lmm-studio eval``): mean
  horizontal speed (cm/s) of a foot's contact point (its toe joint; the database's contacts are toe
  contacts) over the ticks it is in contact, in the pose shown (after IK);
* trajectory following error: distance (m) between the character root and the simulation object;
* transitions per second and searches per second;
* search time per query (us) and controller step time (us).
"""
from __future__ import annotations

import math

import numpy as np


class FootSkating:
    """Foot skating, accumulated: the horizontal (x, z) speed in cm/s of each toe joint from one tick to
    the next, counted for every tick at which that foot is marked in contact (the pose's contact flag,
    no height test), averaged over the counted foot-ticks. Vertical motion never counts as skating.

    :meth:`add` takes one tick (``(2, 3)`` toes) or many at once (``(n, 2, 3)``), so a streaming run
    and a finished run's arrays are measured by the same rule.
    """

    def __init__(self):
        self.sum = np.zeros(2)                    # cm/s summed over the counted ticks, per foot
        self.count = np.zeros(2, dtype=np.int64)  # counted ticks, per foot
        self.max = 0.0

    def add(self, toes_before: np.ndarray, toes_after: np.ndarray, contacts: np.ndarray, dt: float) -> None:
        """Toe positions (m, ``(..., 2, 3)``) at two consecutive ticks ``dt`` s apart and the contacts
        (``(..., 2)`` bool) at the later one."""
        if not dt > 0:
            return
        step = np.asarray(toes_after, np.float64) - np.asarray(toes_before, np.float64)
        speed = np.linalg.norm(step[..., [0, 2]], axis=-1) / dt * 100.0
        contact = np.asarray(contacts, dtype=bool)
        self.sum += np.where(contact, speed, 0.0).reshape(-1, 2).sum(axis=0)
        self.count += contact.reshape(-1, 2).sum(axis=0)
        if contact.any():
            self.max = max(self.max, float(speed[contact].max()))

    def mean_cm_s(self) -> float:
        """Over both feet (NaN when no foot was ever in contact)."""
        n = int(self.count.sum())
        return float(self.sum.sum() / n) if n else float("nan")

    def per_foot_cm_s(self) -> list[float]:
        """Left, right (NaN for a foot never in contact)."""
        return [float(s / n) if n else float("nan") for s, n in zip(self.sum, self.count)]


class MotionMetrics:
    """Feed :meth:`update` one :class:`lmm.controller.DebugSnapshot` per tick, read :meth:`result`."""

    def __init__(self, db):
        self.toe_bones = [db.bone("left_toe"), db.bone("right_toe")]
        self.ticks = 0
        self.seconds = 0.0
        self._prev_toes = None
        self._prev_time = None
        self.skating = FootSkating()
        self._err_sum = 0.0
        self._err_max = 0.0
        self._angle_sum = 0.0
        self.transitions = 0
        self.searches = 0
        self.forced_searches = 0
        self._search_us: list[float] = []
        self._step_us: list[float] = []
        self.non_finite_ticks = 0

    def update(self, snap) -> None:
        pose = snap.pose
        finite = bool(np.isfinite(pose.global_positions).all() and np.isfinite(pose.global_rotations).all())
        if not finite:
            self.non_finite_ticks += 1
        toes = pose.global_positions[self.toe_bones].astype(np.float64)
        if self._prev_toes is not None:
            dt = snap.time_s - self._prev_time
            if dt > 0:
                self.skating.add(self._prev_toes, toes, snap.foot_contacts, dt)
                self.seconds += dt
        self._prev_toes, self._prev_time = toes, snap.time_s
        root = pose.global_positions[0].astype(np.float64)
        err = float(np.linalg.norm(root - snap.simulation_position))
        self._err_sum += err
        self._err_max = max(self._err_max, err)
        self.ticks += 1
        self.transitions += int(snap.transitioned)
        if snap.searched:
            self.searches += 1
            self.forced_searches += int(snap.forced_search)
            if "search" in snap.timings_us:
                self._search_us.append(float(snap.timings_us["search"]))
        if "total" in snap.timings_us:
            self._step_us.append(float(snap.timings_us["total"]))

    def result(self) -> dict:
        """Every metric as a plain JSON-able dict (NaN where nothing was measured)."""
        def med(v):
            return float(np.median(v)) if v else float("nan")

        def mean(v):
            return float(np.mean(v)) if v else float("nan")

        per_foot = self.skating.per_foot_cm_s()
        n_contact = int(self.skating.count.sum())
        seconds = self.seconds if self.seconds > 0 else float("nan")
        return {
            "ticks": self.ticks,
            "seconds": float(self.seconds),
            "foot_skating_cm_s": self.skating.mean_cm_s(),
            "foot_skating_left_cm_s": per_foot[0],
            "foot_skating_right_cm_s": per_foot[1],
            "foot_skating_max_cm_s": float(self.skating.max),
            "contact_fraction": float(n_contact / (2 * max(self.ticks - 1, 1))),
            "trajectory_error_mean_m": float(self._err_sum / self.ticks) if self.ticks else float("nan"),
            "trajectory_error_max_m": float(self._err_max),
            "transitions": self.transitions,
            "transitions_per_s": float(self.transitions / seconds) if self.seconds > 0 else float("nan"),
            "searches": self.searches,
            "forced_searches": self.forced_searches,
            "searches_per_s": float(self.searches / seconds) if self.seconds > 0 else float("nan"),
            "search_us_median": med(self._search_us),
            "search_us_mean": mean(self._search_us),
            "step_us_median": med(self._step_us),
            "step_us_mean": mean(self._step_us),
            "non_finite_ticks": self.non_finite_ticks,
        }


def format_metrics(m: dict) -> str:
    """A readable two-column table of a metrics dict."""
    rows = []
    width = max(len(k) for k in m) if m else 0
    for k, v in m.items():
        if isinstance(v, float):
            text = "nan" if math.isnan(v) else f"{v:.4g}" if abs(v) < 1e4 else f"{v:.0f}"
        else:
            text = str(v)
        rows.append(f"{k.ljust(width)}  {text}")
    return "\n".join(rows)
