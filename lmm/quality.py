"""Motion quality: pops, knee snaps, straight knees, acceleration and jerk, skating and stops, one
definition each, for runs, recordings and the database alike.

Every figure is taken over a fixed time step of 1/30 s (:data:`QUALITY_FPS`; a 60 fps run is sampled
every other tick, other rates are interpolated), so a 60 fps recording and 30 fps mocap are measured on
one time scale and the figures do not depend on the frame rate. The formulas are the kernels below
(:func:`joint_accelerations`, :func:`joint_jerks`, :func:`knee_angles_deg`, :func:`horizontal_speeds`);
:func:`reference_quality` applies them to the database's ranges (whole arrays, exact maxima and
quantiles) and :class:`MotionQuality` to a stream of poses (a window of the last four samples, bounded
memory). The database's own figures are the yardstick:

* a **pop** is a sample at which some joint accelerates harder than anywhere in the database;
* a **knee snap** is a sample at which a knee's angular acceleration exceeds the database's maximum;
* a **straight knee** is a knee bent less than the database's straightest knee (angle between thigh
  and shin, 0 = straight);
* **acceleration p99 at low speed** (root slower than :data:`SLOW_ROOT_M_S`) and **jerk p99**, over
  all joints, as ratios to the database's; beside the first, the same p99 of the database frames the
  controller was playing at those samples, over the same step (:class:`PlayedAccelerations`): how hard
  the motion it plays accelerates by itself there (starts, stops and turns accelerate more than the
  idles that make up most of the database's slow samples), so a reader sees how much the runtime adds;
* **response**: when the desired velocity (the stick, through the speeds) changes by at least
  :data:`STEP_M_S` in one tick (a start, a reversal, a 90-degree turn, a stop), the time until the root's
  velocity is within 1 - :data:`STEP_REACHED` of that change from the desired velocity (the desired
  velocity of the moment: after a reversal it keeps turning with the facing);
* **stops**: after the root (the simulation bone) has moved at least :data:`STOP_FROM_M_S` and comes
  to rest (below :data:`STOPPED_M_S`), the **settle time** is how long until the hips' net movement over
  the next :data:`SETTLED_HOLD_S` is below :data:`SETTLED_HIPS_M_S` on average (the data's own idles sway at
  4-6 cm/s from one sample to the next, so an instantaneous speed would call them unsettled), and the
  **stop toe height** the highest toe
  while the root is below :data:`STOP_FROM_M_S` around that stop (a raised knee shows as a high toe).

Ground skating (:class:`lmm.metrics.GroundSkating`) is fed the same 1/30 s samples by the metrics.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from lmm.data.derived import cached
from lmm.skeleton import joint_of_role

QUALITY_FPS = 30                 # the fixed time step of every figure: 1/30 s
SLOW_ROOT_M_S = 0.5              # "at low speed": the root slower than this
STOP_FROM_M_S = 1.0              # a stop is from at least this root speed; the stop window is below it
STOPPED_M_S = 0.1                # the root has stopped below this
SETTLED_HIPS_M_S = 0.05          # the hips have settled when they move less than this on average ...
SETTLED_HOLD_S = 0.5             # ... over this long (net distance / time: a standing sway cancels, a drift not)
STOP_WINDOW_S = 2.0              # the stop window ends this long after the root stopped (or when it moves on)
SETTLE_LIMIT_S = 1.5             # the bound, reported as a count of stops over it
RAISED_TOE_M = 0.25              # a toe this high in a stop window is a raised leg ...
RAISED_THIGH_DEG = 45.0          # ... a raised knee when its thigh is this far up from hanging straight down
                                 # (the knee lifts; a toe that high behind a near-vertical thigh is a heel kicked
                                 # up in a stride: stepping, 11-30 degrees in the runs' last strides, 71-132 in
                                 # the gestures check-data finds in the takes)
STEP_M_S = 1.0                   # a change of the desired velocity this large in one tick is a step ...
STEP_REACHED = 0.9               # ... reached when the root velocity has closed this share of it
STEP_TIMEOUT_S = 5.0             # ... or never, if not within this
REFERENCE_KEYS = ("max_acceleration", "max_knee_acceleration", "min_knee_angle", "acceleration_p99_slow",
                  "jerk_p99")


@dataclass(frozen=True)
class QualityJoints:
    """The joints the figures need: the root (the simulation bone, joint 0), the hips, and per leg
    (left, right) its hip, knee, ankle and toe joints (the knee is the ankle's parent, the hip the
    knee's)."""
    root: int
    hips: int
    legs: tuple

    @classmethod
    def of(cls, names, parents, bones=None) -> "QualityJoints":
        names, parents = list(names), [int(p) for p in parents]
        hips = joint_of_role(names, bones, "hips")
        legs = []
        for side in ("left", "right"):
            ankle, toe = joint_of_role(names, bones, f"{side}_foot"), joint_of_role(names, bones, f"{side}_toe")
            if ankle is None or toe is None or parents[ankle] < 0 or parents[parents[ankle]] < 0:
                raise ValueError(f"no {side} leg (hip, knee, ankle, toe) in the skeleton")
            knee = parents[ankle]
            legs.append((parents[knee], knee, ankle, toe))
        return cls(root=0, hips=0 if hips is None else hips, legs=tuple(legs))

    @classmethod
    def of_database(cls, db) -> "QualityJoints":
        return cls.of(db.names, db.parents, db.bone_roles)

    @property
    def toes(self) -> list[int]:
        return [leg[3] for leg in self.legs]


# -- the kernels: one definition of each formula, on (n, J, 3) positions sampled every h seconds -----------

def second_differences(x: np.ndarray, h: float) -> np.ndarray:
    """(n - 2, ...) second differences of samples ``h`` seconds apart, at samples 1 .. n - 2."""
    return (x[2:] - 2.0 * x[1:-1] + x[:-2]) / (h * h)


def thigh_raise_deg(hip, knee) -> float:
    """How far a thigh (hip to knee, y up) is raised from hanging straight down, in degrees (90: level)."""
    dx, dy, dz = float(knee[0] - hip[0]), float(knee[1] - hip[1]), float(knee[2] - hip[2])
    n = math.sqrt(dx * dx + dy * dy + dz * dz)
    return math.degrees(math.acos(max(-1.0, min(1.0, -dy / n)))) if n > 0 else 0.0


def joint_accelerations(p: np.ndarray, h: float) -> np.ndarray:
    """(n - 2, J) magnitudes (m/s^2) of the joints' second differences, at samples 1 .. n - 2."""
    return np.linalg.norm(second_differences(p, h), axis=-1)


def joint_jerks(p: np.ndarray, h: float) -> np.ndarray:
    """(n - 3, J) magnitudes (m/s^3) of the third differences."""
    return np.linalg.norm(p[3:] - 3.0 * p[2:-1] + 3.0 * p[1:-2] - p[:-3], axis=-1) / (h * h * h)


def knee_angles_deg(p: np.ndarray, legs) -> np.ndarray:
    """(n, 2) knee angles in degrees: the angle between the thigh (hip to knee) and the shin (knee to
    ankle), 0 for a straight leg."""
    out = []
    for hip, knee, ankle, _ in legs:
        thigh, shin = p[:, knee] - p[:, hip], p[:, ankle] - p[:, knee]
        c = np.einsum("ij,ij->i", thigh, shin) / np.maximum(
            np.linalg.norm(thigh, axis=-1) * np.linalg.norm(shin, axis=-1), 1e-12)
        out.append(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))
    return np.stack(out, axis=-1)


def horizontal_speeds(p: np.ndarray, h: float) -> np.ndarray:
    """(n - 1,) horizontal (x, z) speeds (m/s) of one joint's (n, 3) positions, between samples."""
    return np.hypot(p[1:, 0] - p[:-1, 0], p[1:, 2] - p[:-1, 2]) / h


def resample(positions: np.ndarray, fps: float) -> np.ndarray:
    """(F, J, 3) positions at ``fps`` -> positions every 1/30 s from the first frame (linear
    interpolation; a whole multiple of 30 fps takes every k-th frame exactly)."""
    positions = np.asarray(positions, np.float64)
    ratio = fps / QUALITY_FPS
    if abs(ratio - round(ratio)) < 1e-9 and round(ratio) >= 1:
        return positions[::int(round(ratio))]
    t = np.arange(0.0, (len(positions) - 1) / fps + 1e-9, 1.0 / QUALITY_FPS) * fps
    i = np.minimum(np.floor(t).astype(np.int64), len(positions) - 2)
    w = (t - i)[:, None, None]
    return positions[i] * (1.0 - w) + positions[i + 1] * w


# -- the database's figures ------------------------------------------------------------------------------

def _reference_array(db) -> np.ndarray:
    joints = QualityJoints.of_database(db)
    h = 1.0 / QUALITY_FPS
    acc_max = knee_acc_max = 0.0
    knee_min = math.inf
    slow, jerks = [], []
    for r, (start, stop) in enumerate(zip(db.range_starts, db.range_stops)):
        if db.range_mirrored[r]:
            continue   # the same motion, mirrored: the same figures
        _, pos = db.global_transforms(slice(int(start), int(stop)))
        p = resample(pos, db.fps)
        if len(p) < 4:
            continue
        acc = joint_accelerations(p, h)
        knees = knee_angles_deg(p, joints.legs)
        acc_max = max(acc_max, float(acc.max()))
        knee_acc_max = max(knee_acc_max, float(np.abs(second_differences(knees, h)).max()))
        knee_min = min(knee_min, float(knees.min()))
        root = horizontal_speeds(p[:, joints.root], h)
        centre = 0.5 * (root[1:] + root[:-1])      # the speed at samples 1 .. n - 2
        slow.append(acc[centre < SLOW_ROOT_M_S].ravel())
        jerks.append(joint_jerks(p, h).ravel())
    slow_all = np.concatenate(slow) if slow else np.zeros(0)
    jerk_all = np.concatenate(jerks) if jerks else np.zeros(0)
    return np.array([acc_max, knee_acc_max, knee_min if knee_min < math.inf else float("nan"),
                     float(np.quantile(slow_all, 0.99)) if len(slow_all) else float("nan"),
                     float(np.quantile(jerk_all, 0.99)) if len(jerk_all) else float("nan")])


def reference_quality(db) -> dict:
    """The database's own figures (its source ranges, mirrored copies left out), cached beside its file:
    ``max_acceleration`` (m/s^2), ``max_knee_acceleration`` (deg/s^2), ``min_knee_angle`` (deg),
    ``acceleration_p99_slow`` (m/s^2) and ``jerk_p99`` (m/s^3)."""
    values = cached(db, "quality_reference", [QUALITY_FPS, SLOW_ROOT_M_S], lambda: _reference_array(db))
    return {k: float(v) for k, v in zip(REFERENCE_KEYS, np.asarray(values).tolist())}


# -- a stream of poses -----------------------------------------------------------------------------------

class PlayedAccelerations:
    """The database's own joint accelerations (m/s^2, (J,)) at a frame, over the quality's step: second
    differences of the frames 1/30 s before and after it (interpolated when the database's rate is not a
    multiple of 30 fps), within the frame's range (None where the step leaves it, or for no frame). The
    positions are the database's world positions (its own root path), as :func:`reference_quality` reads
    them. A handful of frames' forward kinematics per call: made only for the low-speed samples."""

    def __init__(self, db):
        self.db = db
        self.step = db.fps / QUALITY_FPS       # frames per 1/30 s
        self.h = 1.0 / QUALITY_FPS

    def __call__(self, frame: int):
        db, r = self.db, self.step
        if frame is None or frame < 0 or frame >= db.n_frames:
            return None
        k = int(db.range_index(frame))
        lo, hi = int(db.range_starts[k]), int(db.range_stops[k])
        if frame - r < lo or frame + r > hi - 1:
            return None
        i = int(math.floor(r))
        w = r - i
        if w < 1e-9:
            _, pos = db.global_transforms(np.array([frame - i, frame, frame + i]))
        else:   # r frames either side fall between whole frames: linear between the two around each
            _, p = db.global_transforms(np.array([frame - i - 1, frame - i, frame, frame + i, frame + i + 1]))
            pos = np.stack([p[1] * (1.0 - w) + p[0] * w, p[2], p[3] * (1.0 - w) + p[4] * w])
        return joint_accelerations(pos, self.h)[0]


class MotionQuality:
    """The figures of a stream of poses, fed one tick at a time (:meth:`add`) in bounded memory.

    ``reference``: the database's figures (:func:`reference_quality`). ``quantiles``: a factory of
    streaming quantile accumulators (``add_many``, ``quantile``) for the p99s. ``played``: a
    :class:`PlayedAccelerations` (or any frame -> accelerations or None), for the p99 of the frames played
    at the low-speed samples; each :meth:`add` then names the database frame its pose plays."""

    def __init__(self, joints: QualityJoints, reference: dict, quantiles, played=None):
        self.joints, self.reference = joints, reference
        self.h = 1.0 / QUALITY_FPS
        self._window = deque(maxlen=4)       # the last samples, (J, 3) each
        self._knees = deque(maxlen=3)        # their knee angles, (2,) each
        self._last_tick = None               # (time, positions) of the previous tick, for interpolation
        self._first = 0.0                    # time of the first sample: the others follow every 1/30 s
        self.samples = 0
        self.pops = 0
        self.knee_snaps = 0
        self.straight_knee_samples = 0
        self.worst = {"pop": (0.0, -1.0), "knee_snap": (0.0, -1.0)}   # (largest value, its time)
        self._slow_acc = quantiles()
        self._jerk = quantiles()
        self.played = played
        self._slow_played = quantiles()
        self._frames = deque(maxlen=4)       # the database frame each sample of the window plays (-1: none)
        # stops: the state machine of :meth:`_stop_step`
        self._peak_speed = 0.0
        self._stop_at = None                 # time the root stopped, while a stop is being watched
        self._window_toe = 0.0               # highest toe since the root fell below STOP_FROM_M_S
        self._window_knee_toe = 0.0          # ... of a leg whose knee was raised (RAISED_THIGH_DEG)
        self._settled_since = None           # start of the first quiet window after the stop
        self._hips_track = deque(maxlen=int(round(SETTLED_HOLD_S * QUALITY_FPS)) + 1)   # (t, x, z)
        self.stops = []                      # (time, settle seconds or None, highest toe m, of a raised knee)
        self.on_sample = None                # optional callback(time, positions) for each sample
        self._desired = None                 # the latest desired velocity (x, z) given to add
        self._step = None                    # (time, start velocity, target velocity) of the step being timed
        self.responses = []                  # seconds to reach each step (inf: not within STEP_TIMEOUT_S)

    def add(self, time_s: float, positions, desired_velocity=None, frame: int = -1) -> None:
        """One tick's world positions (J, 3) at ``time_s`` (increasing); ``desired_velocity`` (3,), when
        given, times the response to its steps; ``frame``: the database frame the pose plays (-1: none),
        for the played frames' figure (the samples this tick makes take it)."""
        p = np.asarray(positions, np.float64)
        frame = int(frame)
        if desired_velocity is not None:
            d = (float(desired_velocity[0]), float(desired_velocity[2]))
            old = self._desired
            if old is not None and math.hypot(d[0] - old[0], d[1] - old[1]) >= STEP_M_S:
                if self._step is not None and time_s - self._step[0] >= STEP_TIMEOUT_S:
                    self.responses.append(math.inf)
                self._step = (time_s, self._root_velocity(), d)   # a new step replaces one not reached yet
            self._desired = d
        last = self._last_tick
        if last is None:
            self._first = time_s
            self._sample(time_s, p, frame)
        else:
            t0, p0 = last
            while True:
                ts = self._first + self.samples * self.h
                if ts > time_s + 1e-9:
                    break
                w = (ts - t0) / (time_s - t0) if time_s > t0 else 1.0
                self._sample(ts, p if abs(1.0 - w) < 1e-6 else p0 + (p - p0) * w, frame)
        self._last_tick = (time_s, p)

    def _sample(self, t: float, p: np.ndarray, frame: int) -> None:
        self.samples += 1
        if self.on_sample is not None:
            self.on_sample(t, p)
        w, h, ref = self._window, self.h, self.reference
        w.append(p)
        self._frames.append(frame)
        knees = knee_angles_deg(p[None], self.joints.legs)[0]
        self._knees.append(knees)
        if float(knees.min()) < ref["min_knee_angle"]:
            self.straight_knee_samples += 1
        if len(w) >= 3:
            arr = np.stack(list(w)[-3:])
            acc = joint_accelerations(arr, h)[0]
            a_max = float(acc.max())
            if a_max > ref["max_acceleration"]:
                self.pops += 1
            if a_max > self.worst["pop"][0]:
                self.worst["pop"] = (a_max, t - h)
            root = horizontal_speeds(arr[:, self.joints.root], h)
            if 0.5 * (root[0] + root[1]) < SLOW_ROOT_M_S:
                self._slow_acc.add_many(acc)
                if self.played is not None:
                    own = self.played(self._frames[-2])     # the frame of the middle sample
                    if own is not None:
                        self._slow_played.add_many(own)
            knee_acc = float(np.abs(second_differences(np.stack(self._knees), h)).max())
            if knee_acc > ref["max_knee_acceleration"]:
                self.knee_snaps += 1
            if knee_acc > self.worst["knee_snap"][0]:
                self.worst["knee_snap"] = (knee_acc, t - h)
        if len(w) >= 4:
            self._jerk.add_many(joint_jerks(np.stack(list(w)), h)[0])
        if len(w) >= 2:
            self._stop_step(t, w[-2], p)
            self._response_step(t)

    def _root_velocity(self) -> tuple[float, float]:
        w, r = self._window, self.joints.root
        if len(w) < 2:
            return (0.0, 0.0)
        return ((w[-1][r, 0] - w[-2][r, 0]) / self.h, (w[-1][r, 2] - w[-2][r, 2]) / self.h)

    def _response_step(self, t: float) -> None:
        if self._step is None:
            return
        t0, (ax, az), (bx, bz) = self._step
        vx, vz = self._root_velocity()
        cx, cz = self._desired     # the desired velocity now: after a reversal or a turn it keeps turning
        if math.hypot(vx - cx, vz - cz) <= (1.0 - STEP_REACHED) * math.hypot(bx - ax, bz - az):
            self.responses.append(t - t0)
            self._step = None
        elif t - t0 > STEP_TIMEOUT_S:
            self.responses.append(math.inf)
            self._step = None

    def _stop_step(self, t: float, prev: np.ndarray, p: np.ndarray) -> None:
        """A stop: the root falls below :data:`STOP_FROM_M_S` (its window opens: the highest toe is kept),
        comes to rest below :data:`STOPPED_M_S` (the stop), and the hips settle; the stop ends when it
        settled and the window has lasted :data:`STOP_WINDOW_S`, when the root moves again, or after 10 s."""
        j, h = self.joints, self.h
        root = math.hypot(p[j.root, 0] - prev[j.root, 0], p[j.root, 2] - prev[j.root, 2]) / h
        track = self._hips_track
        track.append((t, float(p[j.hips, 0]), float(p[j.hips, 2])))
        if root >= STOP_FROM_M_S:
            if self._stop_at is not None:
                self._end_stop(t)
            self._peak_speed, self._window_toe, self._window_knee_toe = max(self._peak_speed, root), 0.0, 0.0
            return
        if self._stop_at is None and self._peak_speed < STOP_FROM_M_S:
            return   # not slowing down from a move
        self._window_toe = max(self._window_toe, max(float(p[i, 1]) for i in j.toes))
        for hip, knee, _, toe in j.legs:
            y = float(p[toe, 1])
            if y > self._window_knee_toe and thigh_raise_deg(p[hip], p[knee]) > RAISED_THIGH_DEG:
                self._window_knee_toe = y
        if self._stop_at is None:
            if root < STOPPED_M_S:
                self._stop_at, self._settled_since, self._peak_speed = t, None, 0.0
            return
        if root > 2.0 * STOPPED_M_S:
            self._end_stop(t)   # moving again
            return
        t0, x0, z0 = track[0]
        if (self._settled_since is None and len(track) == track.maxlen and t0 >= self._stop_at - 1e-9
                and math.hypot(track[-1][1] - x0, track[-1][2] - z0) / (t - t0) < SETTLED_HIPS_M_S):
            self._settled_since = t0
        if (self._settled_time(t) is not None and t - self._stop_at >= STOP_WINDOW_S) or t - self._stop_at > 10.0:
            self._end_stop(t)

    def _settled_time(self, t: float) -> float | None:
        s = self._settled_since
        return None if s is None else max(s - self._stop_at, 0.0)

    def _end_stop(self, t: float) -> None:
        """Record the watched stop: its settle time, +inf when it had not settled after
        :data:`SETTLE_LIMIT_S`, None when the root moved on before that (no verdict)."""
        settle = self._settled_time(t)
        if settle is None and t - self._stop_at >= SETTLE_LIMIT_S:
            settle = math.inf
        self.stops.append((self._stop_at, settle, self._window_toe, self._window_knee_toe))
        self._stop_at, self._settled_since, self._window_toe, self._window_knee_toe = None, None, 0.0, 0.0

    def result(self, prefix: str = "quality_") -> dict:
        minutes = (self.samples - 1) * self.h / 60.0 if self.samples > 1 else float("nan")
        ref = self.reference
        verdicts = [s for _, s, *_ in self.stops if s is not None]      # inf: not settled in SETTLE_LIMIT_S
        settles = [s for s in verdicts if math.isfinite(s)]
        slow_p99, jerk_p99 = self._slow_acc.quantile(0.99), self._jerk.quantile(0.99)
        played_p99 = self._slow_played.quantile(0.99)
        return {
            f"{prefix}pops_per_min": self.pops / minutes if minutes > 0 else float("nan"),
            f"{prefix}knee_snaps_per_min": self.knee_snaps / minutes if minutes > 0 else float("nan"),
            f"{prefix}straight_knee_fraction": self.straight_knee_samples / self.samples if self.samples
            else float("nan"),
            f"{prefix}acceleration_p99_slow_ratio": slow_p99 / ref["acceleration_p99_slow"],
            f"{prefix}acceleration_p99_slow_played_ratio": played_p99 / ref["acceleration_p99_slow"],
            f"{prefix}jerk_p99_ratio": jerk_p99 / ref["jerk_p99"],
            f"{prefix}stops": len(self.stops),
            f"{prefix}settle_s_median": float(np.median(verdicts)) if verdicts else float("nan"),
            f"{prefix}settle_s_max": max(settles) if settles else float("nan"),
            f"{prefix}stops_unsettled": sum(1 for s in verdicts if s > SETTLE_LIMIT_S),
            f"{prefix}stop_toe_max_m": max((toe for _, _, toe, _ in self.stops), default=float("nan")),
            f"{prefix}stops_raised_toe": sum(1 for _, _, toe, _ in self.stops if toe > RAISED_TOE_M),
            f"{prefix}stops_raised_knee": sum(1 for *_, knee in self.stops if knee > RAISED_TOE_M),
            f"{prefix}steps": len(self.responses),
            f"{prefix}response_s_median": float(np.median(self.responses)) if self.responses else float("nan"),
            f"{prefix}response_s_max": max(self.responses) if self.responses else float("nan"),
            f"{prefix}worst_pop_s": self.worst["pop"][1],
            f"{prefix}worst_knee_snap_s": self.worst["knee_snap"][1],
        }


def clip_quality(positions, fps: float, joints: QualityJoints, reference: dict, quantiles,
                 prefix: str = "quality_", frames=None, played=None) -> dict:
    """:class:`MotionQuality`'s figures of a whole clip of world positions (F, J, 3) at ``fps`` (a
    recording, a take): the stream fed frame by frame, so a clip and a run are measured alike.
    ``frames`` (F,), with ``played``: the database frame each pose plays (see :class:`MotionQuality`)."""
    q = MotionQuality(joints, reference, quantiles, played)
    for i, p in enumerate(np.asarray(positions, np.float64)):
        q.add(i / fps, p, None, -1 if frames is None else int(frames[i]))
    return q.result(prefix)
