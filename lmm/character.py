"""The shared character pipeline of motion matching and learned motion matching.

One tick of :meth:`CharacterController.step` reads top to bottom as the animation pipeline::

    input -> desired velocity/rotation -> simulation springs -> predicted trajectory -> query
          -> [search hook, when due] -> inertialize a jump -> [advance hook] -> decay offsets
          -> root integration -> adjustment/clamping -> forward kinematics -> foot locking + IK
          -> snapshot

Subclasses decide only *how the next pose is chosen and produced*, through five hooks:

``_reset_source(frame)``
    Put the pose source at a start state (MM: a database frame; LMM: the projected/compressed state of
    that frame). ``frame`` may be None (the subclass picks).
``_source_features() -> (D,) raw features``
    The matching features of the pose the source is playing now; the query takes its pose channels
    from here (the trajectory channels come from the simulation object).
``_search(query_norm, forced) -> SearchOutcome``
    Called when a search is due (interval elapsed, sharp input change, or ``_must_jump()``). Return an
    outcome; when ``outcome.target`` is a :class:`SourcePose` the source has jumped there, and the
    base class inertializes from the pose on screen to that target. ``target=None``: keep playing.
``_advance_pose(dt) -> SourcePose``
    Advance the source by ``dt`` seconds and return its new pose (the goal that the inertialization
    offsets are added to). Called every tick, after any jump.
``_must_jump() -> bool`` (optional, default False)
    True when the source cannot keep playing (MM: the end of a clip range), which forces a search.

Optional: ``_source_frame()`` (database frame shown in the debugger, default -1),
``_calibration_frame()`` (a database frame of the take the source plays, for ground calibration; default
``_source_frame()``),
``_on_features_changed()`` (feature weights changed: normalised features were rebuilt) and
``_snapshot_extras() -> dict`` (extra :class:`DebugSnapshot` fields, e.g. the LMM latent).

A :class:`SourcePose` is in the database's local form: bone 0 (the simulation/root bone) carries the
root's velocity and angular velocity *in the root's own frame*; its position/rotation are unused,
because the base class integrates the character root in world space itself. Every other bone is local
to its parent, as in :class:`lmm.data.database.Database`.
"""
from __future__ import annotations

import copy
import functools
import math
import struct
import time
import itertools
from dataclasses import dataclass, field

import numpy as np

from lmm import quat
from lmm.data.derived import cached
from lmm.controller import Candidates, Controller, DebugSnapshot, InputState, LazyField, Pose
from lmm.features import build_query_from_columns, normalize_with, trajectory_query_columns
from lmm.ik import FootLockState, solve_leg_floats
from lmm.kinematics import PoseSkeleton, leg_update, pose_forward_kinematics, pose_forward_kinematics_update
from lmm.inertialize import (Offsets, ShownPose, inertialize_apply_pose, inertialize_decay,
                             inertialize_root_velocities, inertialize_transition)
from lmm.springs import damper_factor, halflife_to_damping
from lmm.trajectory import (SimulationFloats, StickWorld, desired_rotation_floats, desired_velocity_floats,
                            simulation_update_floats, trajectory_in_root_space_floats,
                            trajectory_offsets, trajectory_predict_floats)
from lmm.skeleton import subtree
from lmm.tuning import Tuning


@dataclass
class SourcePose:
    """One pose of the source, database skeleton, local form (see the module doc). The velocities may be
    given as a function that makes them (:class:`lmm.controller.LazyField`): only a transition reads them
    (the learned controller's per-tick decoding leaves them to then); ``root_velocities`` then holds bone
    0's (the root's velocity and angular velocity, 3 floats each), which every tick reads."""
    positions: np.ndarray           # (J, 3) local (bone 0 unused)
    rotations: np.ndarray           # (J, 4) local (bone 0 unused)
    velocities: np.ndarray = LazyField()          # (J, 3) local; bone 0: root velocity in the root's frame
    angular_velocities: np.ndarray = LazyField()  # (J, 3) local; bone 0: root angular velocity in its frame
    contacts: np.ndarray            # (2,) bool
    frame: int = -1                 # database frame it came from, if any
    root_velocities: tuple | None = None  # (bone 0's velocity, angular velocity) as float lists, when given
    unit_rotations: bool = False    # the rotations are of unit length to float64 rounding (not float32 data)

    def root_velocity_floats(self) -> tuple[list, list]:
        """Bone 0's velocity and angular velocity as lists of floats (from ``root_velocities`` when given,
        else from the velocity arrays: the same values)."""
        given = self.root_velocities
        if given is not None:
            return given
        return self.velocities[0].tolist(), self.angular_velocities[0].tolist()


@dataclass
class SearchOutcome:
    """What a search (MM) or projection (LMM) decided."""
    target: SourcePose | None       # the pose the source jumped to, None when it keeps playing
    best_frame: int = -1
    best_cost: float = float("nan")
    candidates: Candidates | None = None   # or a function making them when first read (see DebugSnapshot)
    timings_us: dict = field(default_factory=dict)


def database_source_pose(db, frame: int, root_local_velocity=None, root_local_angular_velocity=None) -> SourcePose:
    """Frame ``frame`` of the database as a :class:`SourcePose` (float64)."""
    pos = db.positions[frame].astype(np.float64)
    rot = db.rotations[frame].astype(np.float64)
    vel = db.velocities[frame].astype(np.float64)
    ang = db.angular_velocities[frame].astype(np.float64)
    if root_local_velocity is not None:
        vel[0] = root_local_velocity[frame]
        ang[0] = root_local_angular_velocity[frame]
    else:
        vel[0] = quat.inv_mul_vec(rot[0], vel[0])
        ang[0] = quat.inv_mul_vec(rot[0], ang[0])
    pos[0] = 0.0
    rot[0] = (1.0, 0.0, 0.0, 0.0)
    return SourcePose(pos, rot, vel, ang, db.contacts[frame].copy(), int(frame))


def _made(value):
    """``value``, or what it makes when it is a zero-argument function (a value given for later)."""
    return value() if callable(value) else value


class _SnapshotFeatures:
    """A tick's debug-only feature values for :class:`lmm.controller.DebugSnapshot`'s lazy fields: the
    playing pose's normalised features (``current``), their cost against the query (``cost``) and the
    matched frame's normalised features (``matched``), each computed on first read with the operations
    :meth:`lmm.features.Features.normalize` and the squared distance use. The feature scaling is taken
    now (a weight change replaces those arrays, never writes them), as are the raw features and the
    query (neither is written once made; each may be given as a function that makes it, see
    :meth:`CharacterController._source_features_later` and :meth:`_TickQuery.query`), so a later read
    gives this tick's values."""

    __slots__ = ("_raw", "_mean", "_inv_scale", "_normalized", "_query", "_frame", "_current")

    def __init__(self, features, raw, query, frame: int):
        self._raw, self._query, self._frame = raw, query, int(frame)
        self._mean, self._inv_scale, self._normalized = features.mean, features.inv_scale, features.normalized
        self._current = None

    def current(self) -> np.ndarray:
        if self._current is None:
            self._current = normalize_with(_made(self._raw), self._mean, self._inv_scale)
        return self._current

    def cost(self) -> float:
        query = self._query = _made(self._query)     # the tick's query, worked out on first read (_TickQuery)
        diff = query - self.current()
        diff *= diff                    # the same squares as (query - current) ** 2
        return float(diff.sum())

    def matched(self) -> np.ndarray:
        return self._normalized[self._frame].copy() if self._frame >= 0 else self.current()


def root_local_velocities(db):
    """Every frame's root velocity and angular velocity in the root's own frame, (N, 3) each (cached
    beside the database file, see :mod:`lmm.data.derived`)."""
    def compute():
        r = db.rotations[:, 0].astype(np.float64)
        return np.concatenate([quat.inv_mul_vec(r, db.velocities[:, 0].astype(np.float64)),
                               quat.inv_mul_vec(r, db.angular_velocities[:, 0].astype(np.float64))], axis=1)

    both = cached(db, "root_local_velocities", [], compute, random_access=True)  # read a frame at a time
    return both[:, :3], both[:, 3:]


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


_PACKERS: dict = {}


def _pack_rows(blocks, n: int, dtype) -> tuple:
    """New (n, width) arrays of ``dtype`` (float32 or float64), one per ``(rows, width)`` of ``blocks``
    (``rows``: ``n`` tuples of ``width`` floats), as views of one new buffer: every float packed straight
    into its memory by one :mod:`struct` call (about half the time of ``np.fromiter`` over the chained
    tuples, and one call for a whole pose's arrays). Each float is rounded to float32 as a C cast does, as
    numpy's cast does (the same bits, ``tests/test_frame_cost.py``); with another dtype, or a Python whose
    packing refuses an out-of-range float, numpy converts."""
    dtype = np.dtype(dtype)
    widths = tuple(w for _, w in blocks)
    total = n * sum(widths)
    every = []
    for r, _ in blocks:
        every += r
    flat = None
    if dtype.char in "fd":
        key = (total, dtype.char)
        packer = _PACKERS.get(key)
        if packer is None:
            packer = _PACKERS[key] = struct.Struct(f"={total}{dtype.char}")
        flat = np.empty(total, dtype)
        try:
            packer.pack_into(flat, 0, *itertools.chain.from_iterable(every))
        except (OverflowError, struct.error):
            flat = None
    if flat is None:
        flat = np.fromiter(itertools.chain.from_iterable(every), dtype, total)
    out, start = [], 0
    for w in widths:
        out.append(flat[start:start + n * w].reshape(n, w))
        start += n * w
    return tuple(out)


class _TickQuery:
    """One tick's predicted trajectory (world positions and rotations at the feature offsets) and its
    query (normalised features: the pose channels from the playing pose, the trajectory channels from
    the prediction seen from the character root, as every database frame's features are seen from its
    own root, so a character lagging behind the simulation object asks for the motion that catches up).

    A search needs the query and the debugger both; a tick that does not search needs neither, so each is
    worked out on first call (:class:`lmm.controller.LazyField` takes the methods). Everything they read
    is taken now: the simulation state and goals (tuples), the character root before this tick's
    integration, the playing pose's raw features and the feature scaling (replaced, never written, when
    they change), so a later call gives this tick's values, with the same float operations."""

    __slots__ = ("_args", "_times", "_root", "_source", "_columns", "_mean", "_inv_scale", "_traj", "_query")

    def __init__(self, controller, state, des_vel, des_rot, vel_halflife, rot_halflife, source):
        """``source``: the playing pose's raw features, or a function giving them (see
        :meth:`CharacterController._source_features_later`)."""
        self._args = (*state, des_vel, des_rot, vel_halflife, rot_halflife)
        self._times = controller._traj_times
        self._root = (controller._root_position_t, controller._root_rotation_t)
        self._source = source
        self._columns = controller._query_columns
        features = controller.features
        self._mean, self._inv_scale = features.mean, features.inv_scale
        self._traj = self._query = None

    def _trajectory(self) -> tuple:
        traj = self._traj
        if traj is None:
            traj = self._traj = trajectory_predict_floats(*self._args, self._times)
        return traj

    def positions(self) -> np.ndarray:
        return np.array(self._trajectory()[0])

    def rotations(self) -> np.ndarray:
        return np.array(self._trajectory()[1])

    def query(self) -> np.ndarray:
        if self._query is None:
            traj_pos, traj_rot = self._trajectory()
            local_pos, local_dir = trajectory_in_root_space_floats(traj_pos, traj_rot, *self._root)
            raw = build_query_from_columns(_made(self._source), self._columns, local_pos, local_dir)
            self._query = normalize_with(raw, self._mean, self._inv_scale)
        return self._query


class _LazyRootShift:
    """``controller._root_shift(toes, position, rotation)[i]`` worked out when item ``i`` is read (the foot
    locks read it only for an unlocked foot near the ground): the same floats, often none computed."""
    __slots__ = ("_controller", "_toes", "_position", "_rotation")

    def __init__(self, controller, toes, position, rotation):
        self._controller, self._toes, self._position, self._rotation = controller, toes, position, rotation

    def __getitem__(self, i: int):
        return self._controller._root_shift((self._toes[i],), self._position, self._rotation)[0]


def _norm(v) -> float:
    """Length of one small vector (np.linalg.norm costs several microseconds per call)."""
    v = np.asarray(v, dtype=np.float64).ravel()
    return math.sqrt(float(v @ v))


_DAMPER_FACTORS: dict = {}
_RADIANS: dict = {}


def _damper_factor(halflife: float, dt: float) -> float:
    """1 - exp(-ln2 dt / halflife) (numpy's exp), remembered per (halflife, dt): a tuning changes rarely."""
    key = (halflife, dt)
    f = _DAMPER_FACTORS.get(key)
    if f is None:
        if len(_DAMPER_FACTORS) > 64:
            _DAMPER_FACTORS.clear()
        f = _DAMPER_FACTORS[key] = float(damper_factor(halflife, dt))
    return f


def _integrate_root(root_pos, root_rot, vel, ang, dt) -> tuple:
    """The character root moved by its local velocity ``vel`` and angular velocity ``ang`` (3 floats each)
    for ``dt``: (world velocity, world angular velocity, position, rotation)."""
    vw = quat.mul_vec_scalar(root_rot, vel)
    aw = quat.mul_vec_scalar(root_rot, ang)
    pos = (root_pos[0] + vw[0] * dt, root_pos[1] + vw[1] * dt, root_pos[2] + vw[2] * dt)
    rot = quat.normalize_scalar(quat.mul_scalar(
        quat.from_scaled_angle_axis_scalar((aw[0] * dt, aw[1] * dt, aw[2] * dt)), root_rot))
    return vw, aw, pos, rot


def _radians(degrees: float) -> float:
    """``float(np.radians(degrees))``, remembered per value."""
    r = _RADIANS.get(degrees)
    if r is None:
        if len(_RADIANS) > 64:
            _RADIANS.clear()
        r = _RADIANS[degrees] = float(np.radians(degrees))
    return r


def _array_of(floats: tuple):
    """A function making a new float64 array of ``floats`` (a tuple, never written): a snapshot field
    made when read (see :class:`lmm.controller.LazyField`)."""
    return functools.partial(np.array, floats)


class CharacterController(Controller):
    """The shared pipeline; subclasses implement the source hooks (see the module doc)."""

    name = "character"
    _toe_axes_floats = None  # toe_axes as tuples (filled on first use)
    _contact_height_span = (0, 0, 0.0)  # frames [lo, hi) of the last take looked up, its contact height
    _fk_plan = None  # _FKPlan of the skeleton (made on first use)

    @property
    def desired_velocity(self) -> np.ndarray:
        """The last tick's desired velocity (3,), a new array."""
        return np.array(self._desired_t[0])

    @property
    def desired_rotation(self) -> np.ndarray:
        """The last tick's desired facing rotation (4,), a new array."""
        return np.array(self._desired_t[1])

    def __init__(self, db, features, tuning: Tuning | None = None):
        self.db = db
        # own copy: set_weights replaces the arrays, so two controllers never see each other's weights
        self.features = copy.copy(features)
        self.tuning = tuning if tuning is not None else Tuning()
        self.tuning.validate()
        # a channel the tuning does not name keeps its schema weight (the tuning is only read, never written)
        self._schema_weights = {ch.name: float(w) for ch, w in zip(self.features.layout, self.features.weights)}
        self._weights_stale = True  # a feature weight changed since the features were last weighted
        self.tuning.events.connect(self._on_tuning_change)
        self.parents = [int(p) for p in db.parents]
        self.n_bones = db.n_bones
        self.traj_offsets = trajectory_offsets(self.features)
        self._traj_index = {int(o): i for i, o in enumerate(self.traj_offsets)}
        self._traj_times = tuple((self.traj_offsets / db.fps).tolist())  # the offsets in seconds
        self._query_columns = trajectory_query_columns(self.features, self._traj_index)
        self._weights_seen = None  # the weights array the tuning's feature weights gave, see below
        feet = ("left_foot", "right_foot")
        toes = ("left_toe", "right_toe")
        self.toe_bones = [db.bone(t) for t in toes]
        self.foot_bones = [db.bone(f) for f in feet]
        self.leg_chains = []
        self.toe_axes = []
        for f, t in zip(self.foot_bones, self.toe_bones):
            knee = self.parents[f]
            hip = self.parents[knee]
            self.leg_chains.append((hip, knee, f, t))
            axis = db.positions[0, t].astype(np.float64)
            self.toe_axes.append(axis / max(_norm(axis), 1e-9))
        self._subtrees: dict[tuple, tuple] = {}  # solved legs -> (their bones, their subtrees) for leg-only FK
        self.hips_bone = 1  # the child of the simulation bone; its height is the pose's height
        self._range_contact_height = range_contact_heights(db, self.toe_bones)
        self.reset()

    # ------------------------------------------------------------------------------------------
    # hooks (see module doc)
    # ------------------------------------------------------------------------------------------
    def _reset_source(self, frame: int | None) -> None:
        raise NotImplementedError

    def _source_features(self) -> np.ndarray:
        raise NotImplementedError

    def _source_features_later(self):
        """The playing pose's raw features as they are now, or a zero-argument function that gives them
        later (the same values, for readers that may never ask: see :class:`_TickQuery`)."""
        return self._source_features()

    def _search(self, query_norm: np.ndarray, forced: bool) -> SearchOutcome:
        raise NotImplementedError

    def _advance_pose(self, dt: float) -> SourcePose:
        raise NotImplementedError

    def _must_jump(self) -> bool:
        return False

    def _source_frame(self) -> int:
        return -1

    def _calibration_frame(self) -> int:
        return self._source_frame()

    def _on_features_changed(self) -> None:
        pass

    def _snapshot_extras(self) -> dict:
        return {}

    # ------------------------------------------------------------------------------------------
    # state
    # ------------------------------------------------------------------------------------------
    def reset(self, position=None, rotation=None, frame: int | None = None) -> None:
        position = np.zeros(3) if position is None else np.asarray(position, dtype=np.float64)
        rotation = np.array([1.0, 0, 0, 0]) if rotation is None else quat.normalize(np.asarray(rotation, np.float64))
        self._apply_feature_weights()
        p, q = tuple(position.tolist()), tuple(rotation.tolist())
        self.sim = SimulationFloats((p, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), q, (0.0, 0.0, 0.0)))
        self._desired_t = ((0.0, 0.0, 0.0), q)  # the desired velocity and rotation as float tuples
        self._left_stick, self._right_stick = StickWorld(), StickWorld()
        self._set_root(position.tolist(), rotation.tolist())
        self.stick_released_s = 0.0  # time since the left stick was last outside its deadzone
        self._reset_source(frame)
        pose = self._current_source_pose()
        self.source = pose
        self.shown = (pose.positions.copy(), pose.velocities.copy(), pose.rotations.copy(),
                      pose.angular_velocities.copy())
        self.offsets = Offsets.zeros(self.n_bones)
        self.foot_lock = FootLockState()
        self._prev_toe = None
        self._ground_offset = self._ground_offset_target()
        self._ground_offset_velocity = 0.0
        self._velocity_change_high = False
        self._rotation_change_high = False
        self._since_search = 0.0
        self._needs_search = True
        self.tick = 0
        self.time_s = 0.0
        self._last_candidates = Candidates.empty(len(self.features.layout), self.features.names)
        self._last_best_cost = float("nan")
        self._last_best_frame = -1

    def _current_source_pose(self) -> SourcePose:
        """The source's pose right after a reset (advance by zero)."""
        return self._advance_pose(0.0)

    def _on_tuning_change(self, change) -> None:
        """A tuning change event: feature weights are applied at the next step (or reset)."""
        if change.field == "feature_weights":
            self._weights_stale = True

    def _apply_feature_weights(self) -> bool:
        # every tick: nothing to do unless a weight changed (an event) or the features' weights were replaced
        if not self._weights_stale and self._weights_seen is self.features.weights:
            return False
        self._weights_stale = False
        fw = self.tuning.feature_weights
        new = np.array([fw.get(ch.name, self._schema_weights[ch.name]) for ch in self.features.layout],
                       dtype=np.float32)
        changed = self.features.set_weights(new)
        if changed:
            self._on_features_changed()
        self._weights_seen = self.features.weights
        return changed

    # ------------------------------------------------------------------------------------------
    # the tick
    # ------------------------------------------------------------------------------------------
    def step(self, inp: InputState, dt: float) -> tuple[Pose, DebugSnapshot]:
        t_start = time.perf_counter()
        tun = self.tuning
        timings: dict[str, float] = {}
        self._apply_feature_weights()

        # input -> desired velocity and rotation (camera relative, deadzone); one character's few vectors and
        # quaternions in plain floats (tuples), the same float operations as the numpy forms (tested)
        left = self._left_stick(inp.left_x, inp.left_y, tun.stick_deadzone, inp.camera_azimuth)
        self.stick_released_s = self.stick_released_s + dt if not any(left) else 0.0
        right = self._right_stick(inp.right_x, inp.right_y, tun.stick_deadzone, inp.camera_azimuth)
        sim_state = self.sim.state
        sim_rot = sim_state[3]
        des_vel_t = desired_velocity_floats(left, sim_rot, inp.walk, tun)
        des_rot_t = desired_rotation_floats(left, right, des_vel_t, self._desired_t[1], inp.strafe,
                                            inp.camera_azimuth)
        forced = self._sharp_input_change(des_vel_t, des_rot_t, dt)
        self._desired_t = (des_vel_t, des_rot_t)

        # simulation object and its predicted future
        vel_halflife, rot_halflife = tun.simulation_velocity_halflife_s, tun.simulation_rotation_halflife_s
        state = simulation_update_floats(*sim_state, des_vel_t, des_rot_t, vel_halflife, rot_halflife, dt)
        self.sim = SimulationFloats(state)

        # search when due
        # time since the last search against the interval read now, so a new interval acts at once
        self._since_search += dt
        searched = transitioned = False
        must = self._must_jump()
        search_now = self._needs_search or forced or must or self._since_search >= tun.search_interval_s - 1e-6
        # the predicted trajectory and the query, made now on a tick that searches, else when a reader of
        # the snapshot asks (see _TickQuery): only a search and the debugger use them
        tick_query = _TickQuery(self, state, des_vel_t, des_rot_t, vel_halflife, rot_halflife,
                                self._source_features() if search_now else self._source_features_later())
        query = tick_query.query
        if search_now:
            query = query()
            t0 = time.perf_counter()
            outcome = self._search(query, forced or must)
            timings["search"] = (time.perf_counter() - t0) * 1e6
            timings.update(outcome.timings_us)
            searched = True
            self._needs_search = False
            self._since_search = 0.0
            if outcome.candidates is not None:
                self._last_candidates = outcome.candidates
            self._last_best_cost = outcome.best_cost
            self._last_best_frame = outcome.best_frame
            if outcome.target is not None:
                transitioned = True
                t = outcome.target
                self.offsets = inertialize_transition(*self.shown, t.positions, t.velocities, t.rotations,
                                                      t.angular_velocities)

        # advance the source and blend its pose with the decaying offsets
        t0 = time.perf_counter()
        src = self._advance_pose(dt)
        self.source = src
        timings["advance"] = (time.perf_counter() - t0) * 1e6
        self.offsets = offsets = inertialize_decay(self.offsets, tun.inertialization_halflife_s, dt)
        pos, rot = inertialize_apply_pose(offsets, src.positions, src.rotations, not src.unit_rotations)
        # the shown velocities: bone 0's now (root integration), every bone's when a transition reads them
        vel0, ang0 = inertialize_root_velocities(offsets, *src.root_velocity_floats())
        self.shown = ShownPose(pos, rot, offsets, src)

        # root integration (character space velocities -> world), in plain floats (one 3-vector/quaternion)
        root_vel_world, root_ang_world, root_pos, root_rot = _integrate_root(
            self._root_position_t, self._root_rotation_t, vel0, ang0, dt)
        # the integrated root as floats (tuples, never written): read by the foot locks' root shift
        integrated = (root_pos, root_rot)
        self._synchronize(root_pos, root_rot, root_vel_world, root_ang_world, dt)

        # world pose, then foot locking: forward kinematics, foot locks, leg IK
        t0 = time.perf_counter()
        local_rot, local_pos, g_rot, g_pos, locked = self._world_pose(rot, pos, src.contacts, integrated, dt,
                                                                      np.float32)
        timings["pose"] = (time.perf_counter() - t0) * 1e6

        # ghost: the source pose without offsets, placed at the character root; debug only, so its forward
        # kinematics runs when a reader of the snapshot asks for it (never in headless runs)
        # (a source pose and the root tuples are new every tick, never written in place: the function may
        # read them whenever it is called)
        parents, root_rot, root_pos = self.parents, self._root_rotation_t, self._root_position_t

        def ghost():
            ghost_rot = src.rotations.copy()
            ghost_pos = src.positions.copy()
            ghost_rot[0] = root_rot
            ghost_pos[0] = root_pos
            return np.array(pose_forward_kinematics(ghost_rot, ghost_pos, parents)[1]).astype(np.float32)

        pose = Pose(local_positions=local_pos, local_rotations=local_rot, global_positions=g_pos, global_rotations=g_rot,
                    contacts=np.array(src.contacts, dtype=bool))
        self.tick += 1
        self.time_s = self.tick * dt if dt > 0 else self.time_s
        timings["total"] = (time.perf_counter() - t_start) * 1e6
        frame = self._source_frame()
        # debug-only: the playing pose's normalised features, their cost against the query and the
        # matched frame's features, worked out when a reader asks (see _SnapshotFeatures)
        feats = _SnapshotFeatures(self.features, self._source_features_later(), query, frame)
        # the simulation's and the desired vectors are float tuples (never written): the snapshot's
        # arrays are made from them when read
        snap = DebugSnapshot(
            controller=self.name, tick=self.tick, time_s=self.time_s, input=inp.copy(),
            simulation_position=_array_of(state[0]), simulation_rotation=_array_of(state[3]),
            simulation_velocity=_array_of(state[1]), desired_velocity=_array_of(des_vel_t),
            desired_rotation=_array_of(des_rot_t), trajectory_positions=tick_query.positions,
            trajectory_rotations=tick_query.rotations,
            trajectory_offsets=self.traj_offsets.copy(), query=query, current_features=feats.current,
            matched_frame=int(frame), matched_features=feats.matched,
            candidates=self._last_candidates, searched=searched, forced_search=bool(searched and (forced or must)),
            transitioned=transitioned, best_cost=float(self._last_best_cost), pose=pose,
            matched_pose_positions=ghost, foot_contacts=pose.contacts.copy(),
            foot_locked=locked, timings_us=timings, current_cost=feats.cost,
            **self._snapshot_extras())
        return pose, snap

    # ------------------------------------------------------------------------------------------
    # pieces of the tick
    # ------------------------------------------------------------------------------------------
    def _sharp_input_change(self, des_vel, des_rot, dt) -> bool:
        """True on the tick the desired velocity's (or rotation's) rate of change falls back under the
        threshold after exceeding it: the end of a sharp input change, when the new trajectory is known.
        ``des_vel``/``des_rot``: this tick's desired velocity (3,) and rotation (4,), sequences of floats."""
        if dt <= 0:
            return False
        threshold = self.tuning.forced_search_threshold
        prev_vel, prev_rot = self._desired_t
        d0, d1, d2 = des_vel[0] - prev_vel[0], des_vel[1] - prev_vel[1], des_vel[2] - prev_vel[2]
        vel_rate = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) / dt
        if des_rot == prev_rot and threshold * dt > 1e-12:
            # unchanged: q * conj(q)'s vector part is zero up to a rounding or two of its products (under
            # 1e-15), so its rate stays under the threshold; skip the logarithm
            rot_rate = 0.0
        else:
            rot_rate = quat.norm_scalar(quat.angle_axis_difference_scalar(des_rot, prev_rot)) / dt
        forced = False
        if vel_rate > threshold:
            self._velocity_change_high = True
        elif self._velocity_change_high:
            self._velocity_change_high = False
            forced = True
        if rot_rate > threshold:
            self._rotation_change_high = True
        elif self._rotation_change_high:
            self._rotation_change_high = False
            forced = True
        return forced

    def _world_pose(self, rot, pos, contacts, integrated, dt, dtype=np.float64):
        """The shown local pose (``rot``/``pos``, bone 0 replaced by the character root) in world space,
        with foot locking and leg IK: returns local rotations and positions, global rotations and
        positions (arrays of ``dtype``; the step asks for float32 directly, the same bits as float64
        arrays cast to float32) and the two feet's lock flags ((2,) bool).

        One pose in plain floats (lists of tuples) through forward kinematics, the foot locks, the leg IK
        and the legs' forward kinematics, numpy arrays built once at the end: numpy calls on 3- and
        4-element arrays cost microseconds each. ``integrated`` = the root (position, rotation) before
        adjustment and clamping (see :meth:`_root_shift`)."""
        tun = self.tuning
        rl = rot.tolist()
        pl = pos.tolist()
        rl[0] = self._root_rotation_t
        pl[0] = self._root_position_t
        self._update_ground_offset(dt)
        hips = self.hips_bone
        hip_pos = pl[hips]
        hip_pos[1] += self._ground_offset
        plan = self._fk_plan
        if plan is None:
            plan = self._fk_plan = PoseSkeleton(self.parents, self.leg_chains)
        g_rl, g_pl = pose_forward_kinematics(rl, pl, plan)
        toe_now = [g_pl[t] for t in self.toe_bones]
        locks = self.foot_lock
        if tun.ik_enabled:
            prev = self._prev_toe
            if prev is None or dt <= 0:
                toe_vel = [(0.0, 0.0, 0.0), (0.0, 0.0, 0.0)]
            else:
                toe_vel = [((a[0] - b[0]) / dt, (a[1] - b[1]) / dt, (a[2] - b[2]) / dt) for a, b in zip(toe_now, prev)]
            # the root shift is read only for an unlocked foot near the ground: worked out per foot when read
            shift = _LazyRootShift(self, toe_now, *integrated) if tun.ik_counter_adjustment else None
            targets = locks.update(
                toe_now, toe_vel, contacts.tolist() if isinstance(contacts, np.ndarray) else contacts,
                tun.ik_unlock_radius_m, tun.ik_blend_halflife_s, tun.ik_foot_height_m, dt, tun.ik_lift_height_m,
                tun.ik_ground_blend_speed_m_s, tun.ik_step_height_m, shift, tun.ik_swing_clearance_m)
            axes = self._toe_axes_floats
            if axes is None:
                axes = self._toe_axes_floats = [tuple(a.tolist()) for a in self.toe_axes]
            solved = []
            for i, leg in enumerate(self.leg_chains):
                target, toe = targets[i], toe_now[i]
                is_locked = locks.is_locked(i)
                if not is_locked and (abs(target[0] - toe[0]) <= 1e-6 and abs(target[1] - toe[1]) <= 1e-6
                                      and abs(target[2] - toe[2]) <= 1e-6):
                    continue  # free and fully blended back: nothing to solve
                ground = target[1] - tun.ik_foot_height_m if is_locked else None
                solved.append((i, solve_leg_floats(g_pl, g_rl, leg, target, axes[i], tun.ik_toe_length_m, ground)))
            if solved and plan.legs is not None:
                # per solved leg: its local rotations from the solved globals, then forward kinematics of
                # its chain and subtree (the legs are disjoint subtrees below unchanged bones: the result is
                # the generic form's below, bit for bit)
                for i, rots in solved:
                    chain, parent, rest = plan.legs[i]
                    leg_update(g_rl, g_pl, rl, pl, chain, parent, rots)
                    if rest:
                        pose_forward_kinematics_update(g_rl, g_pl, rl, pl, self.parents, rest)
            elif solved:
                parents = self.parents
                for i, rots in solved:
                    for j, q in zip(self.leg_chains[i], rots):
                        g_rl[j] = q  # the other leg's solve read none of these bones
                key = tuple(i for i, _ in solved)
                found = self._subtrees.get(key)
                if found is None:
                    changed = sorted(j for i in key for j in self.leg_chains[i])
                    found = self._subtrees[key] = (changed, subtree(parents, changed))
                changed, joints = found
                for j in changed:  # local = parent^-1 * global
                    rl[j] = quat.inv_mul_scalar(g_rl[parents[j]], g_rl[j])
                # only the legs changed: forward kinematics of their subtrees, not of the whole skeleton
                pose_forward_kinematics_update(g_rl, g_pl, rl, pl, parents, joints)
        else:
            self.foot_lock = locks = FootLockState()
        locked = np.array([locks.is_locked(0), locks.is_locked(1)])
        self._prev_toe = toe_now
        local_rot, g_rot, g_pos = _pack_rows(((rl, 4), (g_rl, 4), (g_pl, 3)), len(g_rl), dtype)
        local_pos = pos.astype(dtype)
        local_pos[0] = pl[0]
        local_pos[hips, 1] = hip_pos[1]
        return local_rot, local_pos, g_rot, g_pos, locked

    def _root_shift(self, toes, position, rotation) -> list:
        """How far adjustment and clamping moved each toe this tick (two 3-tuples; ``toes`` two 3-tuples):
        the toes as shown minus where they would be with the root left at ``position``/``rotation`` (the
        integrated root). Plain floats, the operations of ``toes - (position + quat.mul_vec(rotation,
        quat.inv_mul_vec(self.root_rotation, toes - self.root_position)))``."""
        px, py, pz = self._root_position_t
        root_rot = self._root_rotation_t
        ox, oy, oz = position.tolist() if isinstance(position, np.ndarray) else position
        rotation = rotation.tolist() if isinstance(rotation, np.ndarray) else rotation
        out = []
        for t in toes:
            back = quat.mul_vec_scalar(rotation, quat.inv_mul_vec_scalar(root_rot, (t[0] - px, t[1] - py, t[2] - pz)))
            out.append((t[0] - (ox + back[0]), t[1] - (oy + back[1]), t[2] - (oz + back[2])))
        return out

    def _ground_offset_target(self) -> float:
        """The height shift (m) that puts the playing take's planted toes at ``ik_foot_height_m`` (0 when
        ground calibration is off, or the source frame or its take's contact height is unknown)."""
        if not self.tuning.ik_ground_calibration:
            return 0.0
        frame = self._calibration_frame()
        if frame < 0 or frame >= len(self.db.contacts):
            return 0.0
        lo, hi, h = self._contact_height_span
        if not lo <= frame < hi:
            # the source plays through a take frame by frame: look the take up when the frame leaves it
            r = int(self.db.range_index(frame))
            stops = self.db.range_stops
            lo = int(stops[r - 1]) if r > 0 else 0  # range_index gives r for stops[r-1] <= frame < stops[r]
            hi = int(stops[r])
            h = float(self._range_contact_height[r])
            self._contact_height_span = (lo, hi, h)
        return self.tuning.ik_foot_height_m - h if math.isfinite(h) else 0.0

    def _update_ground_offset(self, dt: float) -> None:
        """Move the ground calibration shift towards the playing take's (a critically damped spring with
        the inertialization halflife, so a jump to a take calibrated differently does not pop)."""
        target = self._ground_offset_target()
        if dt <= 0:
            return
        y = float(halflife_to_damping(self.tuning.inertialization_halflife_s)) / 2.0
        x, v = self._ground_offset - target, self._ground_offset_velocity
        j1 = v + x * y
        e = math.exp(-y * dt)
        self._ground_offset = target + e * (x + j1 * dt)
        self._ground_offset_velocity = e * (v - j1 * y * dt)

    def _synchronize(self, root_pos, root_rot, root_vel_world, root_ang_world, dt) -> None:
        """Adjustment (pull the integrated character root ``root_pos``/``root_rot``, floats, towards the
        simulation object) and clamping; sets the character root. Plain floats (one position and one
        quaternion), written out: the same operations as the numpy form (tested), a fraction of the time."""
        tun = self.tuning
        sim_state = self.sim.state
        (sx, sy, sz), sim_rot = sim_state[0], sim_state[3]
        px, py, pz = root_pos
        rw, rx, ry, rz = root_rot
        if tun.adjustment_enabled and dt > 0:
            factor = _damper_factor(tun.adjustment_position_halflife_s, dt)
            dx, dy, dz = (sx - px) * factor, (sy - py) * factor, (sz - pz) * factor
            if tun.adjustment_by_velocity:
                vx, vy, vz = root_vel_world
                cap = tun.adjustment_max_speed_ratio * math.sqrt(vx * vx + vy * vy + vz * vz) * dt
                length = math.sqrt(dx * dx + dy * dy + dz * dz)
                if length > cap:
                    k = cap / length
                    dx, dy, dz = dx * k, dy * k, dz * k
            px, py, pz = px + dx, py + dy, pz + dz
            dx, dy, dz = quat.angle_axis_difference_scalar(sim_rot, (rw, rx, ry, rz))
            factor = _damper_factor(tun.adjustment_rotation_halflife_s, dt)
            dx, dy, dz = dx * factor, dy * factor, dz * factor
            if tun.adjustment_by_velocity:
                vx, vy, vz = root_ang_world
                cap = tun.adjustment_max_speed_ratio * math.sqrt(vx * vx + vy * vy + vz * vz) * dt
                length = math.sqrt(dx * dx + dy * dy + dz * dz)
                if length > cap:
                    k = cap / length
                    dx, dy, dz = dx * k, dy * k, dz * k
            rw, rx, ry, rz = quat.normalize_scalar(quat.mul_scalar(quat.from_scaled_angle_axis_scalar((dx, dy, dz)),
                                                                   (rw, rx, ry, rz)))
        if tun.clamping_enabled:
            ox, oy, oz = px - sx, py - sy, pz - sz
            dist = math.sqrt(ox * ox + oy * oy + oz * oz)
            max_dist = tun.clamp_max_distance_m
            if dist > max_dist:
                k = max_dist / dist
                px, py, pz = sx + ox * k, sy + oy * k, sz + oz * k
            dx, dy, dz = quat.angle_axis_difference_scalar((rw, rx, ry, rz), sim_rot)
            angle = math.sqrt(dx * dx + dy * dy + dz * dz)
            max_angle = _radians(tun.clamp_max_angle_deg)
            if angle > max_angle:
                k = max_angle / angle
                rw, rx, ry, rz = quat.normalize_scalar(quat.mul_scalar(
                    quat.from_scaled_angle_axis_scalar((dx * k, dy * k, dz * k)), sim_rot))
        self._set_root((px, py, pz), (rw, rx, ry, rz))

    def _set_root(self, position, rotation) -> None:
        """Set the character root (3 and 4 floats, kept as tuples; :attr:`root_position` and
        :attr:`root_rotation` are arrays made from them when read)."""
        self._root_position_t = tuple(position)
        self._root_rotation_t = tuple(rotation)

    @property
    def root_position(self) -> np.ndarray:
        """The character root's position, (3,) float64 (a new array)."""
        return np.array(self._root_position_t)

    @property
    def root_rotation(self) -> np.ndarray:
        """The character root's rotation, (4,) float64 (a new array)."""
        return np.array(self._root_rotation_t)
