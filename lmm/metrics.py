"""Motion quality and cost metrics, accumulated from per-tick debug snapshots (streaming, O(1) memory).

* foot skating (:class:`FootSkating`, the one definition, also used by ``lmm-studio eval``): mean
  horizontal speed (cm/s) of a foot's contact point (its toe joint; the database's contacts are toe
  contacts) over the ticks it is in contact, in the pose shown (after IK);
* ground skating (:class:`GroundSkating`, :func:`ground_skating`, the one definition for runs, ``eval``
  and the source takes, :func:`source_ground_skating`): the fraction of ground-level toe steps whose
  horizontal speed over a 1/30 s step exceeds 30 cm/s. It needs no contact flags, so recordings and mocap
  are measured alike;
* motion quality (:mod:`lmm.quality`): pops, knee snaps, straight knees, acceleration and jerk p99 as
  ratios to the database's own, stops and settling;
* trajectory following error: distance (m) between the character root and the simulation object;
* transitions per second and searches per second;
* search time per query (us) and controller step time (us);
* tag shares: per tag of the database, the fraction of ticks whose playing frame's range has it (ticks
  with a playing database frame only: the learned controller has one only with its debug comparison on).
"""
from __future__ import annotations

import math

import numpy as np

from lmm.data.derived import cached
from lmm.quality import QUALITY_FPS, MotionQuality, PlayedAccelerations, QualityJoints, reference_quality, resample


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


GROUND_BAND_M = 0.02          # a toe within this of its lowest level is at ground level
GROUND_SPEED_M_S = 0.30       # faster than this along the ground is skating
GROUND_FLOOR_PERCENTILE = 5.0  # "its lowest level": this low percentile of the toe's heights
_BIN_M = 0.001                # height histogram resolution
_BIN_LOW_M, _BIN_HIGH_M = -1.0, 3.0
_N_BINS = int(round((_BIN_HIGH_M - _BIN_LOW_M) / _BIN_M))


class GroundSkating:
    """Ground skating, accumulated in bounded memory (height histograms, never the frames).

    A *step* is one toe from one frame to the next. It is at ground level when the toe is at ground
    level at both ends: its height within :data:`GROUND_BAND_M` (2 cm) above the floor. It skates when its
    horizontal (x, z) speed exceeds :data:`GROUND_SPEED_M_S` (30 cm/s). The result is the fraction of
    ground-level steps that skate, over both toes.

    The floor, per toe, is either given (``floor_m``) or the toe's own lowest level over everything added:
    the :data:`GROUND_FLOOR_PERCENTILE` th percentile of its heights. The percentile, not the minimum,
    because a few frames far below the rest (an IK or blending artefact in a recording, a marker glitch
    in mocap) would otherwise set the floor; per toe and per clip, because mocap takes differ in their
    floor calibration by a few centimetres. Recordings and source takes use the same rule, so their
    figures compare. Heights are binned at 1 mm (floor and band are exact to the bin).
    """

    def __init__(self, floor_m: float | None = None):
        self.floor_m = floor_m
        self.heights = np.zeros((2, _N_BINS), dtype=np.int64)    # frames per height bin, per toe
        self.steps = np.zeros((2, _N_BINS), dtype=np.int64)      # steps per bin of the step's higher end
        self.fast = np.zeros((2, _N_BINS), dtype=np.int64)       # of those, the ones faster than the limit
        self._last = None  # the last frame's toes seen by add_frame

    @staticmethod
    def _bins(y: np.ndarray) -> np.ndarray:
        return np.clip(np.floor((np.asarray(y, np.float64) - _BIN_LOW_M) / _BIN_M), 0, _N_BINS - 1).astype(np.int64)

    def add(self, toes: np.ndarray, dt: float) -> None:
        """A clip of toe positions (m, ``(F, 2, 3)``, F >= 1) at ``dt`` s per frame; its first frame is not
        joined to anything added before (use :meth:`add_frame` to stream)."""
        toes = np.asarray(toes, np.float64).reshape(-1, 2, 3)
        if not dt > 0 or len(toes) == 0:
            return
        for i in range(2):
            np.add.at(self.heights[i], self._bins(toes[:, i, 1]), 1)
        if len(toes) < 2:
            return
        speed = np.linalg.norm(np.diff(toes[..., [0, 2]], axis=0), axis=-1) / dt
        high = self._bins(np.maximum(toes[1:, :, 1], toes[:-1, :, 1]))
        for i in range(2):
            np.add.at(self.steps[i], high[:, i], 1)
            np.add.at(self.fast[i], high[speed[:, i] > GROUND_SPEED_M_S, i], 1)

    def add_frame(self, toes: np.ndarray, dt: float) -> None:
        """One frame (``(2, 3)``) of a stream, ``dt`` s after the previous one (plain floats: this runs
        every tick)."""
        (lx, ly, lz), (rx, ry, rz) = (tuple(float(v) for v in t) for t in toes)
        for i, y in ((0, ly), (1, ry)):
            self.heights[i, min(max(int(math.floor((y - _BIN_LOW_M) / _BIN_M)), 0), _N_BINS - 1)] += 1
        last = self._last
        self._last = ((lx, ly, lz), (rx, ry, rz))
        if last is None or not dt > 0:
            return
        for i, (x, y, z) in enumerate(self._last):
            px, py, pz = last[i]
            b = min(max(int(math.floor((max(y, py) - _BIN_LOW_M) / _BIN_M)), 0), _N_BINS - 1)
            self.steps[i, b] += 1
            if math.hypot(x - px, z - pz) / dt > GROUND_SPEED_M_S:
                self.fast[i, b] += 1

    def floor_bins(self) -> list[int]:
        """Per toe, the bin of its floor (-1 for a toe with no frames)."""
        if self.floor_m is not None:
            b = int(self._bins(np.array([self.floor_m]))[0])
            return [b, b]
        out = []
        for i in range(2):
            n = int(self.heights[i].sum())
            if n == 0:
                out.append(-1)
                continue
            rank = GROUND_FLOOR_PERCENTILE / 100.0 * n
            out.append(int(np.searchsorted(np.cumsum(self.heights[i]), max(rank, 1), side="left")))
        return out

    def counts(self) -> tuple[int, int]:
        """(skating steps, ground-level steps), over both toes."""
        band = int(round(GROUND_BAND_M / _BIN_M))
        fast = ground = 0
        for i, b in enumerate(self.floor_bins()):
            if b < 0:
                continue
            fast += int(self.fast[i, :b + band + 1].sum())
            ground += int(self.steps[i, :b + band + 1].sum())
        return fast, ground

    def fraction(self) -> float:
        """Skating steps / ground-level steps (NaN when no step was at ground level)."""
        fast, ground = self.counts()
        return fast / ground if ground else float("nan")

    def result(self, prefix: str = "ground_skating") -> dict:
        fast, ground = self.counts()
        return {f"{prefix}_fraction": fast / ground if ground else float("nan"),
                f"{prefix}_steps": fast, f"{prefix}_ground_steps": ground}


def ground_skating(toes: np.ndarray, fps: float, floor_m: float | None = None) -> dict:
    """The ground skating of one clip of toe positions (m, ``(F, 2, 3)``) at ``fps``, taken over 1/30 s
    steps (:func:`lmm.quality.resample`) like every motion figure: a dict with ``fraction`` (NaN when no
    step was at ground level), ``skating_steps`` and ``ground_steps`` (see :class:`GroundSkating` for the
    rule and the floor)."""
    g = GroundSkating(floor_m)
    toes = np.asarray(toes, np.float64).reshape(-1, 2, 3)
    if len(toes) > 1:
        g.add(resample(toes, fps), 1.0 / QUALITY_FPS)
    fast, ground = g.counts()
    return {"fraction": fast / ground if ground else float("nan"), "skating_steps": fast, "ground_steps": ground}


def source_ground_skating(db, include_mirrored: bool = False) -> dict:
    """Ground skating of the database's source ranges (the mocap), each range with its own floor, counts
    summed over ranges; mirrored copies are left out by default (they hold the same steps). The counts
    are cached beside the database file."""
    fast, ground = (int(v) for v in cached(db, "source_ground_skating", [bool(include_mirrored), QUALITY_FPS],
                                           lambda: _source_ground_skating_counts(db, include_mirrored)))
    return {"fraction": fast / ground if ground else float("nan"), "skating_steps": fast, "ground_steps": ground}


def _source_ground_skating_counts(db, include_mirrored: bool) -> np.ndarray:
    toes = [db.bone("left_toe"), db.bone("right_toe")]
    fast = ground = 0
    for r, (start, stop) in enumerate(zip(db.range_starts, db.range_stops)):
        if db.range_mirrored[r] and not include_mirrored:
            continue
        _, toe_pos = db.global_transforms_of(toes, slice(int(start), int(stop)))
        one = ground_skating(toe_pos, db.fps)
        fast += one["skating_steps"]
        ground += one["ground_steps"]
    return np.array([fast, ground], dtype=np.int64)


class DurationStats:
    """Count, mean and median of a stream of durations (e.g. microseconds per step) in constant memory.

    A run of hours feeds millions of values, so they are not kept: the first :attr:`EXACT` values are
    held exactly (a short run's median is exact), and from then on every value goes into a histogram of
    log-spaced bins :data:`BIN_RATIO` wide (1 %) from :data:`LOW` to :data:`HIGH`, so the median is
    within 0.5 % of the true one. The mean is exact. Memory: ``EXACT`` floats plus the bins (~45 KB).
    """

    EXACT = 2048
    LOW, HIGH = 1e-3, 1e9          # values outside are counted in the first / last bin
    BIN_RATIO = 1.01
    N_BINS = int(math.ceil(math.log(HIGH / LOW) / math.log(BIN_RATIO)))

    def __init__(self):
        self.count = 0
        self.sum = 0.0
        self._exact = np.empty(self.EXACT, np.float64)
        self._bins: np.ndarray | None = None     # allocated when the exact buffer is full

    def add(self, value: float) -> None:
        value = float(value)
        if self.count < self.EXACT:
            self._exact[self.count] = value
        else:
            if self._bins is None:
                self._bins = np.zeros(self.N_BINS, np.int64)
                np.add.at(self._bins, self._bin(self._exact), 1)
            ratio = max(value, self.LOW) / self.LOW      # plain floats: this runs every tick
            self._bins[min(int(math.log(ratio) / math.log(self.BIN_RATIO)), self.N_BINS - 1)] += 1
        self.count += 1
        self.sum += value

    def add_many(self, values) -> None:
        """:meth:`add` of each value, in one go (a pose's joints)."""
        v = np.asarray(values, np.float64).ravel()
        room = max(self.EXACT - self.count, 0)
        head, tail = v[:room], v[room:]
        self._exact[self.count:self.count + len(head)] = head
        if len(tail):
            if self._bins is None:
                self._bins = np.zeros(self.N_BINS, np.int64)
                np.add.at(self._bins, self._bin(self._exact), 1)
            np.add.at(self._bins, self._bin(tail), 1)
        self.count += len(v)
        self.sum += float(v.sum())

    def _bin(self, v):
        ratio = np.maximum(np.asarray(v, np.float64), self.LOW) / self.LOW
        return np.clip(np.floor(np.log(ratio) / math.log(self.BIN_RATIO)), 0, self.N_BINS - 1).astype(np.int64)

    def mean(self) -> float:
        return self.sum / self.count if self.count else float("nan")

    def quantile(self, q: float) -> float:
        """The ``q`` quantile (0..1): exact while at most ``EXACT`` values came, else to a bin's 1 %."""
        if self.count == 0:
            return float("nan")
        if self._bins is None:
            return float(np.quantile(self._exact[:self.count], q))
        rank = q * (self.count - 1)
        b = int(np.searchsorted(np.cumsum(self._bins), rank + 1, side="left"))
        return float(self.LOW * self.BIN_RATIO ** (b + 0.5))   # the bin's geometric centre

    def median(self) -> float:
        return self.quantile(0.5)


class MotionMetrics:
    """Feed :meth:`update` one :class:`lmm.controller.DebugSnapshot` per tick, read :meth:`result`."""

    def __init__(self, db):
        self.toe_bones = [db.bone("left_toe"), db.bone("right_toe")]
        self.ticks = 0
        self.seconds = 0.0
        self._prev_toes = None
        self._prev_time = None
        self.skating = FootSkating()
        self.ground = GroundSkating()   # fed the quality's 1/30 s samples: one time step for every figure
        joints = QualityJoints.of_database(db)
        self.quality = MotionQuality(joints, reference_quality(db), DurationStats, PlayedAccelerations(db))
        toes = joints.toes
        self.quality.on_sample = lambda t, p: self.ground.add_frame(p[toes], self.quality.h)
        self._err_sum = 0.0
        self._err_max = 0.0
        self._angle_sum = 0.0
        self.transitions = 0
        self.searches = 0
        self.forced_searches = 0
        self._search_us = DurationStats()   # bounded: a long run must not grow (no per-tick lists)
        self._step_us = DurationStats()
        self.non_finite_ticks = 0           # ticks whose pose was unusable (pose_problem), none recorded
        self.first_bad_tick, self.first_bad_problem = None, ""
        self._tag_names = list(db.tag_names)
        self._frame_tags = db.frame_tags if self._tag_names else None   # (N, T) bool
        self._tag_counts = np.zeros(len(self._tag_names), dtype=np.int64)
        self._tagged_ticks = 0          # ticks with a playing database frame

    def update(self, snap) -> bool:
        """Add one tick; False when its pose is unusable (:func:`pose_problem`): counted in
        ``non_finite_ticks`` (the first one's tick and reason kept), left out of every other metric, and
        the caller records nothing for it."""
        pose = snap.pose
        problem = pose_problem(pose)
        if problem is not None:
            self.non_finite_ticks += 1
            if self.first_bad_tick is None:
                self.first_bad_tick, self.first_bad_problem = int(snap.tick), problem
            self.ticks += 1
            return False
        toes = pose.global_positions[self.toe_bones].astype(np.float64)
        if self._prev_toes is not None:
            dt = snap.time_s - self._prev_time
            if dt > 0:
                self.skating.add(self._prev_toes, toes, snap.foot_contacts, dt)
                self.seconds += dt
        self.quality.add(snap.time_s, pose.global_positions, getattr(snap, "desired_velocity", None),
                         getattr(snap, "matched_frame", -1))
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
                self._search_us.add(snap.timings_us["search"])
        if "total" in snap.timings_us:
            self._step_us.add(snap.timings_us["total"])
        frame = snap.matched_frame
        if self._frame_tags is not None and 0 <= frame < len(self._frame_tags):
            self._tag_counts += self._frame_tags[frame]
            self._tagged_ticks += 1
        return True

    def result(self) -> dict:
        """Every metric as a plain JSON-able dict (NaN where nothing was measured)."""
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
            **self.ground.result(),
            **self.quality.result(),
            "contact_fraction": float(n_contact / (2 * max(self.ticks - 1, 1))),
            "trajectory_error_mean_m": float(self._err_sum / self.ticks) if self.ticks else float("nan"),
            "trajectory_error_max_m": float(self._err_max),
            "transitions": self.transitions,
            "transitions_per_s": float(self.transitions / seconds) if self.seconds > 0 else float("nan"),
            "searches": self.searches,
            "forced_searches": self.forced_searches,
            "searches_per_s": float(self.searches / seconds) if self.seconds > 0 else float("nan"),
            "search_us_median": self._search_us.median(),
            "search_us_mean": self._search_us.mean(),
            "step_us_median": self._step_us.median(),
            "step_us_mean": self._step_us.mean(),
            "non_finite_ticks": self.non_finite_ticks,
            **{f"tag_share_{name}": float(n / self._tagged_ticks) if self._tagged_ticks else float("nan")
               for name, n in zip(self._tag_names, self._tag_counts.tolist())},
        }


#: farthest a joint may be from the origin (metres): 1000 km, more than a day of running at 10 m/s. A
#: network given absurd weights produced joints 2e9 m away (finite, so nothing noticed them) that our
#: own BVH reader then refused in the recording.
MAX_POSE_DISTANCE_M = 1e6


def pose_problem(pose) -> str | None:
    """Why a pose cannot be used (recorded, measured), or None: a NaN or infinite position or rotation
    (a network fed weights it cannot handle), or a joint farther than :data:`MAX_POSE_DISTANCE_M`."""
    # checked every tick by run, replay and the studio: the largest distance is NaN or inf exactly when a
    # position is, so the positions take one pass
    far = float(np.abs(pose.global_positions).max(initial=0.0))
    if not (math.isfinite(far) and np.isfinite(pose.global_rotations).all()):
        return "not finite (NaN or infinite positions or rotations)"
    if far > MAX_POSE_DISTANCE_M:
        return f"a joint {far:.3g} m from the origin (more than {MAX_POSE_DISTANCE_M:g} m)"
    return None


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
