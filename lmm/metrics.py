"""Motion quality and cost metrics, accumulated from per-tick debug snapshots (streaming, O(1) memory).

* foot skating: mean horizontal speed (cm/s) of a foot's contact point (its toe joint; the database's
  contacts are toe contacts) over the ticks it is in contact, in the pose shown (after IK);
* trajectory following error: distance (m) between the character root and the simulation object;
* transitions per second and searches per second;
* search time per query (us) and controller step time (us).
"""
from __future__ import annotations

import math

import numpy as np


class MotionMetrics:
    """Feed :meth:`update` one :class:`lmm.controller.DebugSnapshot` per tick, read :meth:`result`."""

    def __init__(self, db):
        self.toe_bones = [db.bone("left_toe"), db.bone("right_toe")]
        self.ticks = 0
        self.seconds = 0.0
        self._prev_toes = None
        self._prev_time = None
        self._skate_sum = np.zeros(2)
        self._skate_n = np.zeros(2, dtype=np.int64)
        self._skate_max = 0.0
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
                speed = np.linalg.norm((toes - self._prev_toes)[:, [0, 2]], axis=-1) / dt * 100.0  # cm/s
                contact = np.asarray(snap.foot_contacts, dtype=bool)
                self._skate_sum += np.where(contact, speed, 0.0)
                self._skate_n += contact
                if contact.any():
                    self._skate_max = max(self._skate_max, float(speed[contact].max()))
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

        per_foot = [float(s / n) if n else float("nan") for s, n in zip(self._skate_sum, self._skate_n)]
        n_contact = int(self._skate_n.sum())
        seconds = self.seconds if self.seconds > 0 else float("nan")
        return {
            "ticks": self.ticks,
            "seconds": float(self.seconds),
            "foot_skating_cm_s": float(self._skate_sum.sum() / n_contact) if n_contact else float("nan"),
            "foot_skating_left_cm_s": per_foot[0],
            "foot_skating_right_cm_s": per_foot[1],
            "foot_skating_max_cm_s": float(self._skate_max),
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
