"""The studio's live motion quality (:mod:`lmm.quality`): each controller's pops, knee snaps, straight
knees and stops since the last reset, as the Stats panel's quality rows, and the latest flagged moments."""
from __future__ import annotations

import math

from lmm.metrics import DurationStats, pose_problem
from lmm.quality import MotionQuality, PlayedAccelerations, QualityJoints, reference_quality

SHORT = {"mm": "MM", "lmm": "LMM"}


def _num(v, fmt: str) -> str:
    """``v`` formatted, or "-" when nothing was measured (NaN, inf, None)."""
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


class LiveQuality:
    """One :class:`lmm.quality.MotionQuality` per controller, fed every tick's shown pose."""

    def __init__(self, db):
        self.joints = QualityJoints.of_database(db)
        self.reference = reference_quality(db)
        self.played = PlayedAccelerations(db)
        self.by_name: dict[str, MotionQuality] = {}

    def reset(self) -> None:
        self.by_name = {}

    def add(self, time_s: float, snaps: dict) -> dict[str, int]:
        """Each usable pose of the tick; returns per controller how many moments this tick flagged."""
        flagged = {}
        for name, snap in snaps.items():
            pose = snap.pose
            if pose_problem(pose) is not None:
                continue
            q = self.by_name.get(name)
            if q is None:
                q = self.by_name[name] = MotionQuality(self.joints, self.reference, DurationStats, self.played)
            before = q.pops + q.knee_snaps + q.straight_knee_samples
            q.add(time_s, pose.global_positions, snap.desired_velocity, snap.matched_frame)
            flagged[name] = q.pops + q.knee_snaps + q.straight_knee_samples - before
        return flagged

    def text(self) -> str:
        """One line per controller: its figures since the last reset (ratios to the database's own)."""
        lines = []
        for name, q in self.by_name.items():
            if q.samples < 4:
                continue
            r = q.result("")
            lines.append(f"{SHORT.get(name, name)} quality: {_num(r['pops_per_min'], '.1f')} pops/min, "
                         f"{_num(r['knee_snaps_per_min'], '.1f')} knee snaps/min, straight knee "
                         f"{_num(100 * r['straight_knee_fraction'], '.1f')} %, jerk p99 "
                         f"{_num(r['jerk_p99_ratio'], '.2f')}x data, slow accel p99 "
                         f"{_num(r['acceleration_p99_slow_ratio'], '.2f')}x (frames played "
                         f"{_num(r['acceleration_p99_slow_played_ratio'], '.2f')}x), stops {r['stops']} "
                         f"({r['stops_unsettled']} slow to settle)")
        return "\n".join(lines)
