"""Ground calibration: takes differ by a few centimetres in where their mocap puts the floor, so the pose is
shifted up or down by the playing take's own planted-toe height (:class:`GroundCalibration`, its per-take
heights from :func:`range_contact_heights`)."""
from __future__ import annotations

import math

import numpy as np

from lmm.data.derived import cached
from lmm.springs import decay_spring_damper_scalar, halflife_to_damping


def bone_heights(db, bones) -> np.ndarray:
    """World heights (F, len(bones)) of the given bones in every database frame: forward kinematics along
    each bone's chain only (a handful of bones, not the whole skeleton; see
    :meth:`lmm.data.database.Database.global_transforms_of`)."""
    return db.global_transforms_of([int(b) for b in bones])[1][:, :, 1]


def range_contact_heights(db, toe_bones, min_frames: int = 10) -> np.ndarray:
    """Per clip range, the median height (m) of the toes over the frames where they are in contact: where
    that take's mocap puts a planted toe joint (takes differ by a few centimetres in floor calibration).
    The median, not a low percentile: a low percentile shifts every take up by the spread of its planted
    heights (about 0.6 cm on the default data), which lifts running flight phases with it (both toes
    above 15 cm: 1.07 % of a 600 s random run with the 10th percentile, 0.68 % with the median); a planted
    toe left below foot height is lifted by its lock by a few millimetres, which nobody sees.
    A range with fewer than ``min_frames`` contact toe-frames gets the database's median; NaN for every
    range when the database has no contact at all. Cached beside the database file."""
    return cached(db, "range_contact_heights", [[int(t) for t in toe_bones], int(min_frames)],
                  lambda: _range_contact_heights(db, toe_bones, min_frames))


def _range_contact_heights(db, toe_bones, min_frames: int) -> np.ndarray:
    n_ranges = len(db.range_starts)
    heights = bone_heights(db, toe_bones)
    contacts = np.asarray(db.contacts, dtype=bool)
    out = np.full(n_ranges, np.nan)
    if not contacts.any():
        return out
    overall = float(np.median(heights[contacts]))
    for r, (start, stop) in enumerate(zip(db.range_starts, db.range_stops)):
        h = heights[int(start):int(stop)][contacts[int(start):int(stop)]]
        out[r] = float(np.median(h)) if len(h) >= min_frames else overall
    return out


class GroundCalibration:
    """The height shift (m) of the shown pose, ``offset``, and its velocity: moved towards the playing
    take's target by :meth:`update`, set to it by :meth:`reset`. The take's contact height is looked up
    when the source's frame leaves the take last looked up (kept across resets)."""
    __slots__ = ("db", "_range_heights", "_span", "offset", "velocity")

    def __init__(self, db, toe_bones):
        self.db = db
        self._range_heights = range_contact_heights(db, toe_bones)
        self._span = (0, 0, 0.0)  # frames [lo, hi) of the last take looked up, its contact height
        self.offset = self.velocity = 0.0

    def reset(self, tuning, frame: int) -> None:
        self.offset = self.target(tuning, frame)
        self.velocity = 0.0

    def target(self, tuning, frame: int) -> float:
        """The height shift (m) that puts the playing take's planted toes at ``ik_foot_height_m`` (0 when
        ground calibration is off, or the source frame or its take's contact height is unknown)."""
        if not tuning.ik_ground_calibration:
            return 0.0
        if frame < 0 or frame >= len(self.db.contacts):
            return 0.0
        lo, hi, h = self._span
        if not lo <= frame < hi:
            # the source plays through a take frame by frame: look the take up when the frame leaves it
            r = int(self.db.range_index(frame))
            stops = self.db.range_stops
            lo = int(stops[r - 1]) if r > 0 else 0  # range_index gives r for stops[r-1] <= frame < stops[r]
            hi = int(stops[r])
            h = float(self._range_heights[r])
            self._span = (lo, hi, h)
        return tuning.ik_foot_height_m - h if math.isfinite(h) else 0.0

    def update(self, tuning, frame: int, dt: float) -> None:
        """Move the ground calibration shift towards the playing take's (a critically damped spring with
        the inertialization halflife, so a jump to a take calibrated differently does not pop)."""
        target = self.target(tuning, frame)
        if dt <= 0:
            return
        y = float(halflife_to_damping(tuning.inertialization_halflife_s)) / 2.0
        x, self.velocity = decay_spring_damper_scalar(self.offset - target, self.velocity, y, math.exp(-y * dt), dt)
        self.offset = target + x
