"""What the Coverage panel (:mod:`.coverage`) says about one controller's query: where it lies on the
map, its nearest database frame and cost, and its asked-for speed and turning rate."""
from __future__ import annotations

import numpy as np

from lmm.coverage import Coverage, DataDistance, query_speed_turn


class QueryReport:
    """What the panel shows about one controller's query at the displayed tick (plain data)."""

    def __init__(self, cov: Coverage, distance: DataDistance, features, snap, trail_queries: np.ndarray,
                 horizon: int, fps: float):
        q = np.asarray(snap.query, np.float64)
        self.xy = cov.project_query(q, features.inv_scale)
        trail = trail_queries[np.all(np.isfinite(trail_queries), axis=1)] if trail_queries.ndim == 2 else q[None]
        self.trail = cov.project_query(trail, features.inv_scale) if len(trail) else self.xy[None]
        self.nearest_frame, self.cost = distance.nearest(q)
        self.speed, self.turn = query_speed_turn(snap.trajectory_positions, snap.trajectory_rotations,
                                                 snap.trajectory_offsets, snap.pose.global_positions[0],
                                                 snap.pose.global_rotations[0], horizon, fps)
        self.cell_seconds = cov.heatmap.seconds_at(self.speed, self.turn)
        self.raw = features.denormalize(np.asarray(snap.query, np.float32)).astype(np.float64)

    def to_dict(self) -> dict:
        f = lambda v: None if v is None or not np.isfinite(v) else float(v)  # noqa: E731
        return {"xy": self.xy.tolist(), "trail_points": int(len(self.trail)), "nearest_frame": int(self.nearest_frame),
                "cost": f(self.cost), "speed_m_s": f(self.speed), "turn_deg_s": f(self.turn),
                "cell_seconds": f(self.cell_seconds)}


def distance_for(features) -> tuple:
    """(the normalised features it was built on, :class:`DataDistance` over them): a panel's nearest-frame
    search, made again when a weight change replaces the array."""
    return features.normalized, DataDistance(features.normalized)
