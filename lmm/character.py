"""The shared character pipeline of motion matching and learned motion matching.

One tick of :meth:`CharacterController.step` reads top to bottom as the animation pipeline, one method
per stage::

    _desired_motion            input -> desired velocity/rotation (lmm.trajectory)
    _simulate                  simulation springs (lmm.springs through lmm.trajectory)
    _search_when_due           predicted trajectory and query (lmm.tick_snapshot.TickQuery) -> [search hook]
                               -> inertialize a jump (lmm.inertialize)
    _advance_and_inertialize   [advance hook] -> decay offsets -> root integration, adjustment/clamping
                               (lmm.root_motion)
    _world_pose                ground calibration (lmm.ground) -> forward kinematics (lmm.kinematics)
                               -> foot locking + leg IK (lmm.ik) -> arrays (lmm.pose_rows)
    then the snapshot, whose debug-only fields are worked out when read (lmm.tick_snapshot)

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

A :class:`lmm.source_pose.SourcePose` is in the database's local form: bone 0 (the simulation/root bone) carries the
root's velocity and angular velocity *in the root's own frame*; its position/rotation are unused,
because the base class integrates the character root in world space itself. Every other bone is local
to its parent, as in :class:`lmm.data.database.Database`.
"""
from __future__ import annotations

import copy
import math
import time

import numpy as np

from lmm import quat
from lmm.controller import Candidates, Controller, DebugSnapshot, InputState, Pose
from lmm.features import trajectory_query_columns
from lmm.ground import GroundCalibration
from lmm.ik import FootLockState, solve_legs
from lmm.inertialize import (Offsets, ShownPose, inertialize_apply_pose, inertialize_decay,
                             inertialize_root_velocities, inertialize_transition)
from lmm.kinematics import PoseSkeleton, pose_forward_kinematics, pose_update_legs
from lmm.pose_rows import pack_rows
from lmm.root_motion import LazyRootShift, integrate_root, synchronize
from lmm.search import candidate_mask
from lmm.source_pose import SearchOutcome, SourcePose
from lmm.tick_snapshot import SnapshotFeatures, TickQuery, array_of, ghost_positions
from lmm.trajectory import (SharpInputChange, SimulationState, StickWorld, desired_rotation, desired_velocity,
                            simulation_update, trajectory_offsets)
from lmm.tuning import Tuning

INERTIALIZATION_SLOW_M_S = 1.0   # at this simulation speed and over, pose jumps blend out with the (short) halflife


class CharacterController(Controller):
    """The shared pipeline; subclasses implement the source hooks (see the module doc)."""

    name = "character"
    _toe_axes_floats = None  # toe_axes as tuples (filled on first use)
    _fk_plan = None  # PoseSkeleton of the skeleton and its legs (made on first use)
    _candidate_mask = None  # (exclude_range_end_frames, the mask it gave), made on first use

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
            self.toe_axes.append(axis / max(math.sqrt(float(axis @ axis)), 1e-9))
        self.hips_bone = db.bone("hips")  # the manifest's hips role; its height is the pose's height
        self.ground = GroundCalibration(db, self.toe_bones)
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
        later (the same values, for readers that may never ask: see :class:`lmm.tick_snapshot.TickQuery`)."""
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
        self.sim = SimulationState((p, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), q, (0.0, 0.0, 0.0)))
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
        self.ground.reset(self.tuning, self._calibration_frame())
        self._sharp_change = SharpInputChange()
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
        timings: dict[str, float] = {}
        self._apply_feature_weights()
        des_vel, des_rot, forced = self._desired_motion(inp, dt)
        state = self._simulate(des_vel, des_rot, dt)
        tick_query, searched, transitioned, must = self._search_when_due(state, des_vel, des_rot, forced, dt, timings)
        src, pos, rot, integrated = self._advance_and_inertialize(dt, timings)
        t0 = time.perf_counter()
        local_rot, local_pos, g_rot, g_pos, locked = self._world_pose(rot, pos, src.contacts, integrated, dt,
                                                                      np.float32)
        timings["pose"] = (time.perf_counter() - t0) * 1e6
        pose = Pose(local_positions=local_pos, local_rotations=local_rot, global_positions=g_pos, global_rotations=g_rot,
                    contacts=np.array(src.contacts, dtype=bool))
        self.tick += 1
        self.time_s = self.tick * dt if dt > 0 else self.time_s
        timings["total"] = (time.perf_counter() - t_start) * 1e6
        frame = self._source_frame()
        query = tick_query.query if not searched else tick_query.query()
        # debug-only: the playing pose's normalised features, their cost against the query and the matched
        # frame's features, the ghost, the snapshot's arrays of the tick's float tuples: made when read
        feats = SnapshotFeatures(self.features, self._source_features_later(), query, frame)
        snap = DebugSnapshot(
            controller=self.name, tick=self.tick, time_s=self.time_s, input=inp.copy(),
            simulation_position=array_of(state[0]), simulation_rotation=array_of(state[3]),
            simulation_velocity=array_of(state[1]), desired_velocity=array_of(des_vel),
            desired_rotation=array_of(des_rot), trajectory_positions=tick_query.positions,
            trajectory_rotations=tick_query.rotations,
            trajectory_offsets=self.traj_offsets.copy(), query=query, current_features=feats.current,
            matched_frame=int(frame), matched_features=feats.matched,
            candidates=self._last_candidates, searched=searched, forced_search=bool(searched and (forced or must)),
            transitioned=transitioned, best_cost=float(self._last_best_cost), pose=pose,
            matched_pose_positions=ghost_positions(src, self._root_position_t, self._root_rotation_t, self.parents),
            foot_contacts=pose.contacts.copy(), foot_locked=locked, timings_us=timings, current_cost=feats.cost,
            **self._snapshot_extras())
        return pose, snap

    # ------------------------------------------------------------------------------------------
    # the stages of the tick, in order
    # ------------------------------------------------------------------------------------------
    def _desired_motion(self, inp: InputState, dt: float) -> tuple:
        """Input -> desired velocity and rotation (camera relative, deadzone), as float tuples, and whether
        a sharp input change just ended (a search is forced)."""
        tun = self.tuning
        left = self._left_stick(inp.left_x, inp.left_y, tun.stick_deadzone, inp.camera_azimuth)
        self.stick_released_s = self.stick_released_s + dt if not any(left) else 0.0
        right = self._right_stick(inp.right_x, inp.right_y, tun.stick_deadzone, inp.camera_azimuth)
        des_vel = desired_velocity(left, self.sim.state[3], inp.walk, tun)
        des_rot = desired_rotation(left, right, des_vel, self._desired_t[1], inp.strafe, inp.camera_azimuth)
        forced = self._sharp_change(des_vel, des_rot, *self._desired_t, tun.forced_search_threshold, dt)
        self._desired_t = (des_vel, des_rot)
        return des_vel, des_rot, forced

    def _simulate(self, des_vel, des_rot, dt: float) -> tuple:
        """The simulation object one spring step towards the desired motion; returns its state tuple."""
        tun = self.tuning
        state = simulation_update(*self.sim.state, des_vel, des_rot, tun.simulation_velocity_halflife_s,
                                         tun.simulation_rotation_halflife_s, dt)
        self.sim = SimulationState(state)
        return state

    def _search_when_due(self, state, des_vel, des_rot, forced: bool, dt: float, timings: dict) -> tuple:
        """The search hook when due (interval elapsed, sharp input change, source at its end), and the
        inertialization of a jump. Returns (the tick's :class:`TickQuery`, searched, transitioned, must)."""
        tun = self.tuning
        # time since the last search against the interval read now, so a new interval acts at once
        self._since_search += dt
        must = self._must_jump()
        search_now = self._needs_search or forced or must or self._since_search >= tun.search_interval_s - 1e-6
        # the predicted trajectory and the query, made now on a tick that searches, else when a reader of
        # the snapshot asks (see TickQuery): only a search and the debugger use them
        tick_query = TickQuery(self, state, des_vel, des_rot, tun.simulation_velocity_halflife_s,
                               tun.simulation_rotation_halflife_s,
                               self._source_features() if search_now else self._source_features_later())
        if not search_now:
            return tick_query, False, False, must
        t0 = time.perf_counter()
        outcome = self._search(tick_query.query(), forced or must)
        timings["search"] = (time.perf_counter() - t0) * 1e6
        timings.update(outcome.timings_us)
        self._needs_search = False
        self._since_search = 0.0
        if outcome.candidates is not None:
            self._last_candidates = outcome.candidates
        self._last_best_cost = outcome.best_cost
        self._last_best_frame = outcome.best_frame
        t = outcome.target
        if t is not None:
            self.offsets = inertialize_transition(*self.shown, t.positions, t.velocities, t.rotations,
                                                  t.angular_velocities)
        return tick_query, True, t is not None, must

    def _advance_and_inertialize(self, dt: float, timings: dict) -> tuple:
        """Advance the source, blend its pose with the decaying offsets, move the character root (its
        velocities integrated, then adjustment and clamping). Returns (source pose, shown local positions,
        rotations, the integrated root before adjustment as tuples)."""
        tun = self.tuning
        t0 = time.perf_counter()
        src = self.source = self._advance_pose(dt)
        timings["advance"] = (time.perf_counter() - t0) * 1e6
        self.offsets = offsets = inertialize_decay(self.offsets, self._inertialization_halflife(), dt)
        pos, rot = inertialize_apply_pose(offsets, src.positions, src.rotations, not src.unit_rotations)
        # the shown velocities: bone 0's now (root integration), every bone's when a transition reads them
        vel0, ang0 = inertialize_root_velocities(offsets, *src.root_velocity_floats())
        self.shown = ShownPose(pos, rot, offsets, src)
        root_vel_world, root_ang_world, root_pos, root_rot = integrate_root(
            self._root_position_t, self._root_rotation_t, vel0, ang0, dt)
        self._set_root(*synchronize(tun, self.sim.state, root_pos, root_rot, root_vel_world, root_ang_world, dt))
        return src, pos, rot, (root_pos, root_rot)

    # ------------------------------------------------------------------------------------------
    # what the search may jump to (both controllers)
    # ------------------------------------------------------------------------------------------
    def candidate_mask(self) -> np.ndarray:
        """Frames that may be jumped to under the current tuning (the last frame of a range never)."""
        end = max(int(self.tuning.exclude_range_end_frames), 1)
        cached = self._candidate_mask
        if cached is None or cached[0] != end:
            cached = self._candidate_mask = (end, candidate_mask(self.db.n_frames, self.db.range_starts,
                                                                  self.db.range_stops, end))
        return cached[1]

    def idle_set_active(self) -> bool:
        """The stick has been released long enough for the search to keep to the idle set (see
        :class:`lmm.tuning.Tuning`)."""
        tun = self.tuning
        return bool(tun.idle_set_enabled) and self.stick_released_s >= tun.idle_delay_s - 1e-9

    def _inertialization_halflife(self) -> float:
        """The offsets' halflife this tick: ``inertialization_slow_halflife_s`` with the simulation object at
        rest, blended linearly to ``inertialization_halflife_s`` at :data:`INERTIALIZATION_SLOW_M_S` and over
        (rounded to 0.01 s: the decay keeps its constants per halflife)."""
        tun = self.tuning
        fast, slow = tun.inertialization_halflife_s, tun.inertialization_slow_halflife_s
        if slow <= 0.0 or slow == fast:
            return fast
        v = self.sim.state[1]
        w = min(math.sqrt(v[0] * v[0] + v[2] * v[2]) / INERTIALIZATION_SLOW_M_S, 1.0)
        return round((slow + (fast - slow) * w) * 100.0) / 100.0

    def _world_pose(self, rot, pos, contacts, integrated, dt, dtype=np.float64):
        """The shown local pose (``rot``/``pos``, bone 0 replaced by the character root) in world space,
        with foot locking and leg IK: returns local rotations and positions, global rotations and
        positions (arrays of ``dtype``; the step asks for float32 directly, the same bits as float64
        arrays cast to float32) and the two feet's lock flags ((2,) bool).

        One pose in plain floats (lists of tuples) through forward kinematics, the foot locks, the leg IK
        and the legs' forward kinematics, numpy arrays built once at the end: numpy calls on 3- and
        4-element arrays cost microseconds each. ``integrated`` = the root (position, rotation) before
        adjustment and clamping (see :func:`lmm.root_motion.root_shift`)."""
        tun = self.tuning
        rl = rot.tolist()
        pl = pos.tolist()
        rl[0] = self._root_rotation_t
        pl[0] = self._root_position_t
        self.ground.update(tun, self._calibration_frame(), dt)
        hips = self.hips_bone
        hip_pos = pl[hips]
        hip_pos[1] += self.ground.offset
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
            shift = (LazyRootShift(self._root_position_t, self._root_rotation_t, toe_now, *integrated)
                     if tun.ik_counter_adjustment else None)
            # standing (the stick released past the idle delay), a foot still planted where the stride left
            # it steps to the standing pose sooner: the idle's stance, not a frozen stride
            standing = tun.ik_idle_unlock_radius_m > 0.0 and self.stick_released_s >= tun.idle_delay_s
            targets = locks.update(
                toe_now, toe_vel, contacts.tolist() if isinstance(contacts, np.ndarray) else contacts,
                min(tun.ik_unlock_radius_m, tun.ik_idle_unlock_radius_m) if standing else tun.ik_unlock_radius_m, tun.ik_blend_halflife_s, tun.ik_foot_height_m, dt, tun.ik_lift_height_m,
                tun.ik_ground_blend_speed_m_s, tun.ik_step_height_m, shift, tun.ik_swing_clearance_m,
                tun.ik_lock_max_speed_m_s, tun.ik_lock_follow_m_s, tun.ik_step_halflife_s,
                tun.ik_ground_blend_acceleration_m_s2)
            axes = self._toe_axes_floats
            if axes is None:
                axes = self._toe_axes_floats = [tuple(a.tolist()) for a in self.toe_axes]
            solved = solve_legs(locks, g_pl, g_rl, self.leg_chains, targets, axes, tun.ik_toe_length_m,
                                tun.ik_foot_height_m, math.cos(math.radians(tun.ik_min_knee_deg)),
                                tun.ik_soft_reach_m, dt, math.radians(tun.ik_knee_max_acceleration_deg_s2))
            if solved:  # only the legs changed: forward kinematics of their subtrees, not the whole skeleton
                pose_update_legs(plan, g_rl, g_pl, rl, pl, solved)
        else:
            self.foot_lock = locks = FootLockState()
        locked = np.array([locks.is_locked(0), locks.is_locked(1)])
        self._prev_toe = toe_now
        local_rot, g_rot, g_pos = pack_rows(((rl, 4), (g_rl, 4), (g_pl, 3)), len(g_rl), dtype)
        local_pos = pos.astype(dtype)
        local_pos[0] = pl[0]
        local_pos[hips, 1] = hip_pos[1]
        return local_rot, local_pos, g_rot, g_pos, locked

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
