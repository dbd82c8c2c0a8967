"""A simulated character that tracks a kinematic one: a stable-PD ragdoll in MuJoCo.

Each 60 Hz tick the tracked pose (an MM or LMM :class:`lmm.controller.Pose`) becomes a target ``qpos`` of
the :class:`lmm.physics.body.Body`; the ragdoll is stepped ``substeps`` times towards it. Every ball joint
is driven by a stable PD controller (Tan, Liu and Turk 2011, *Stable Proportional-Derivative Controllers*):

    tau = kp * (q_target - (q + h * qdot)) + kd * (qdot_target - qdot_next)

The spring looks one substep ahead (``q + h qdot``) and the damper acts on the *next* velocity, which
MuJoCo's implicit integrator treats implicitly when ``kd`` is the joint damping: both make high gains
stable at a coarse step. Gains scale with the mass each joint moves (its subtree), so the same settings fit
bodies of any size.

The root (hips' free joint) is not actuated: a real body only moves itself through the feet on the
floor. With ``residual`` on, the same stable PD acts on the root as well ("the hand of god"); its force
and torque are the *residual* the motion needs beyond what the joints and contacts give, reported per
tick as a fraction of body weight. Without it the ragdoll must balance by tracking alone and falls when it
cannot: a fall is the head below ``fall_head_fraction`` of the tracked head height, or a mean joint
position error above ``fall_error_m``; :meth:`Ragdoll.reset` puts it back on the tracked pose, and
``reset_after_fall_s`` does so by itself.

``mujoco`` is imported lazily (:func:`lmm.physics.require_mujoco`); nothing else here needs it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lmm.physics import require_mujoco
from lmm.physics.body import GRAVITY_M_S2, Body, body_for_database  # noqa: F401  (re-exported)

SIDES = ("left", "right")


@dataclass
class RagdollSettings:
    """The tunables of a :class:`Ragdoll`; changed values act on the next tick (gains are re-read)."""
    residual: bool = True              # the root residual force ("hand of god") is on
    substeps: int = 8                  # physics steps per tick (60 Hz tick: 480 Hz physics)
    joint_stiffness: float = 600.0     # kp per kg moved by the joint (N m / rad / kg)
    joint_damping_s: float = 0.08      # kd / kp (s)
    root_stiffness: float = 900.0      # residual kp per kg (N / m / kg; torque per kg m^2 likewise), 1/s^2
    root_damping_ratio: float = 1.0    # residual damping, critical at 1
    fall_head_fraction: float = 0.5    # fallen: head below this fraction of the tracked head height ...
    fall_error_m: float = 0.5          # ... or a mean joint position error above this
    reset_after_fall_s: float = 1.0    # a fallen ragdoll goes back on the tracked pose after this (0: never)
    lift_out_of_floor: bool = True     # track the pose raised until no sole point is below the floor


@dataclass
class RagdollTick:
    """What one tick of the ragdoll gives (its pose in the tracked skeleton and what it cost)."""
    positions: np.ndarray              # (J, 3) the ragdoll's joint positions (m), the tracked skeleton's joints
    residual_force_bw: float           # |root residual force| / body weight (0 when the residual is off)
    residual_torque_bw_m: float        # |root residual torque| / body weight (m)
    tracking_error_cm: float           # mean joint position error against the tracked pose (raised, see lift_m)
    foot_contacts: np.ndarray          # (2,) bool: left, right foot touches the floor
    fallen: bool                       # it has fallen (and was not reset yet)
    falls: int                         # falls since the ragdoll was made (or :meth:`Ragdoll.clear_falls`)
    reset: bool = False                # it was put back on the tracked pose this tick


class Ragdoll:
    """A stable-PD ragdoll of ``body`` tracking a pose each tick of ``dt`` seconds (see the module doc)."""

    def __init__(self, body: Body, dt: float = 1.0 / 60.0, settings: RagdollSettings | None = None):
        mujoco = require_mujoco("the ragdoll")
        self._mj = mujoco
        self.body = body
        self.dt = float(dt)
        self.settings = settings if settings is not None else RagdollSettings()
        # a private model: the ragdoll sets its timestep and joint damping
        self.model = mujoco.MjModel.from_xml_string(body.xml)
        # ball-joint limits count from the skeleton's rest rotation, which some takes (LAFAN1's hips-to-thigh
        # and clavicle joints, about 180 degrees) sit far from in every frame: the PD targets keep the pose
        self.model.jnt_limited[:] = 0
        self.data = mujoco.MjData(self.model)
        self.head = int(body.key_joints["head"])
        self.joints = np.asarray(body.joints, np.int64)
        self.body_ids = np.asarray(body.body_id[self.joints], np.int64)
        self.root_mass = float(self.model.body_subtreemass[body.body_id[body.root]])
        self._foot_geom_side = {int(g): i for i, s in enumerate(SIDES) for g in body.foot_geoms[s]}
        self.falls = 0
        self.fallen = False
        self._fallen_ticks = 0
        self._target = None                 # the last tick's target qpos
        self.last_residual_force = np.zeros(3)   # the last tick's mean root residual force (N, world frame)
        self._gains_of = None
        self._apply_gains()

    # -- gains -----------------------------------------------------------------------------------
    def _apply_gains(self) -> None:
        s = self.settings
        key = (s.substeps, s.joint_stiffness, s.joint_damping_s, s.root_stiffness, s.root_damping_ratio, s.residual)
        if key == self._gains_of:
            return
        m, b = self.model, self.body
        m.opt.timestep = self.dt / max(int(s.substeps), 1)
        nv = m.nv
        kp = np.zeros(nv)
        subtree = np.asarray(m.body_subtreemass)
        for j in self.joints[1:]:
            a = int(b.dof_adr[j])
            kp[a:a + 3] = s.joint_stiffness * subtree[b.body_id[j]]
        kd = kp * s.joint_damping_s
        # the root: a critically damped spring per unit mass (linear) and per unit rotational inertia
        mass = self.root_mass
        inertia = float(np.sum(self._root_inertia()) / 3.0)
        w = np.sqrt(s.root_stiffness)
        kp[0:3], kd[0:3] = s.root_stiffness * mass, 2.0 * s.root_damping_ratio * w * mass
        kp[3:6], kd[3:6] = s.root_stiffness * inertia, 2.0 * s.root_damping_ratio * w * inertia
        if not s.residual:
            kp[0:6] = kd[0:6] = 0.0
        self.kp, self.kd = kp, kd
        m.dof_damping[:] = kd          # implicit in the integrator: the damper acts on the next velocity
        self._gains_of = key

    def _root_inertia(self) -> np.ndarray:
        """The whole body's rotational inertia about its centre of mass, roughly (diagonal, kg m^2)."""
        d = self._mj.MjData(self.model)
        self._mj.mj_forward(self.model, d)
        masses = np.asarray(self.model.body_mass)[1:]
        pos = np.asarray(d.xipos)[1:]
        com = (masses[:, None] * pos).sum(0) / max(masses.sum(), 1e-9)
        r2 = ((pos - com) ** 2)
        return np.array([(masses * (r2[:, 1] + r2[:, 2])).sum(), (masses * (r2[:, 0] + r2[:, 2])).sum(),
                         (masses * (r2[:, 0] + r2[:, 1])).sum()]) + 1e-3

    # -- state -----------------------------------------------------------------------------------
    def target_qpos(self, global_pos, global_rot) -> np.ndarray:
        """The ``qpos`` the ragdoll tracks for a pose: the pose's own, raised out of the floor when
        ``lift_out_of_floor`` (a sole sunk into the floor would push the feet against the root's residual
        spring: kinematic poses often sink a few centimetres)."""
        q = self.body.qpos_from_pose(global_pos, global_rot)
        q[1] += self.lift_m(global_pos, global_rot)
        return q

    def lift_m(self, global_pos, global_rot) -> float:
        """How far the tracked pose is raised (m): its lowest sole point's depth below the floor, or 0."""
        if not self.settings.lift_out_of_floor:
            return 0.0
        return max(0.0, -float(self.body.sole_points(global_pos, global_rot)[:, 1].min()))

    def reset(self, global_pos, global_rot, velocity_qvel=None) -> None:
        """Put the ragdoll on a pose (global positions (J, 3) m and rotations (J, 4)), at rest or moving
        with ``velocity_qvel`` (nv,)."""
        mj, d = self._mj, self.data
        q = self.target_qpos(global_pos, global_rot)
        mj.mj_resetData(self.model, d)
        d.qpos[:] = q
        d.qvel[:] = 0.0 if velocity_qvel is None else velocity_qvel
        mj.mj_forward(self.model, d)
        self._target = q
        self.fallen = False
        self._fallen_ticks = 0

    def clear_falls(self) -> None:
        self.falls = 0

    # -- one tick --------------------------------------------------------------------------------
    def step(self, global_pos, global_rot) -> RagdollTick:
        """Track the pose of this tick (global positions (J, 3) m and rotations (J, 4) of the body's
        skeleton): ``substeps`` stable-PD steps towards it, then the fall check."""
        mj, m, d, s = self._mj, self.model, self.data, self.settings
        pos = np.asarray(global_pos, np.float64)
        rot = np.asarray(global_rot, np.float64)
        lift = self.lift_m(pos, rot)
        target = self.body.qpos_from_pose(pos, rot)
        target[1] += lift
        reset = False
        if self._target is None:
            self.reset(pos, rot)
            reset = True
        elif self.fallen and s.reset_after_fall_s > 0 and self._fallen_ticks * self.dt >= s.reset_after_fall_s:
            vt = np.empty(m.nv)
            mj.mj_differentiatePos(m, vt, self.dt, self._target, target)
            self.reset(pos, rot, vt)
            reset = True
        self._apply_gains()
        n = max(int(s.substeps), 1)
        h = self.dt / n
        vt = np.empty(m.nv)
        mj.mj_differentiatePos(m, vt, self.dt, self._target, target)
        qt = self._target.copy()
        ahead = np.empty(m.nq)
        err = np.empty(m.nv)
        kp, kd = self.kp, self.kd
        drive = kd * vt
        force = np.zeros(3)
        torque = np.zeros(3)
        for _ in range(n):
            mj.mj_integratePos(m, qt, vt, h)                 # the target moves along the tick
            ahead[:] = d.qpos
            mj.mj_integratePos(m, ahead, d.qvel, h)
            mj.mj_differentiatePos(m, err, 1.0, ahead, qt)
            tau = kp * err + drive
            d.qfrc_applied[:] = tau
            mj.mj_step(m, d)
            if s.residual:               # the damper's share acts on the new velocity
                force += tau[0:3] - kd[0:3] * d.qvel[0:3]
                torque += tau[3:6] - kd[3:6] * d.qvel[3:6]
        self._target = target
        self.last_residual_force = force / n
        weight = self.body.total_mass * GRAVITY_M_S2
        xpos = np.asarray(d.xpos)
        here = pos.copy()
        here[self.joints] = xpos[self.body_ids]
        # joints without a body (a ground-projected simulation bone) move with the hips over the ground
        shift = here[self.body.root] - pos[self.body.root]
        shift[1] = 0.0
        outside = np.setdiff1d(np.arange(len(pos)), self.joints)
        here[outside] = pos[outside] + shift
        # the error against what it tracks (the pose raised out of the floor)
        error = float(np.linalg.norm(here[self.joints] - pos[self.joints] - [0.0, lift, 0.0], axis=1).mean())
        head_low = here[self.head, 1] < s.fall_head_fraction * max(pos[self.head, 1], 1e-3)
        if not self.fallen and (head_low or error > s.fall_error_m):
            self.fallen = True
            self.falls += 1
            self._fallen_ticks = 0
        if self.fallen:
            self._fallen_ticks += 1
        return RagdollTick(positions=here, residual_force_bw=float(np.linalg.norm(force) / n / weight),
                           residual_torque_bw_m=float(np.linalg.norm(torque) / n / weight),
                           tracking_error_cm=100.0 * error, foot_contacts=self.foot_contacts(),
                           fallen=self.fallen, falls=self.falls, reset=reset)

    def foot_contacts(self) -> np.ndarray:
        """(2,) bool: a sole box of the left / right foot touches the floor now."""
        out = np.zeros(2, bool)
        d = self.data
        if d.ncon:
            geoms = np.asarray(d.contact.geom)[: d.ncon]
            for g in geoms.reshape(-1):
                side = self._foot_geom_side.get(int(g))
                if side is not None:
                    out[side] = True
        return out


@dataclass
class TrackingSummary:
    """A ragdoll's tracking of one run: what :func:`track_run` measured."""
    ticks: int
    mean_error_cm: float
    max_error_cm: float
    falls: int
    mean_residual_bw: float
    median_residual_bw: float
    contact_fraction: np.ndarray = field(default_factory=lambda: np.zeros(2))   # left, right
    ms_per_tick: float = 0.0


def summarize(ticks: list[RagdollTick], seconds_per_tick_s: float = 0.0) -> TrackingSummary:
    """Mean/max tracking error, falls and residual of a run's :class:`RagdollTick` list."""
    err = np.array([t.tracking_error_cm for t in ticks]) if ticks else np.zeros(1)
    res = np.array([t.residual_force_bw for t in ticks]) if ticks else np.zeros(1)
    contacts = np.array([t.foot_contacts for t in ticks]) if ticks else np.zeros((1, 2))
    return TrackingSummary(ticks=len(ticks), mean_error_cm=float(err.mean()), max_error_cm=float(err.max()),
                           falls=int(ticks[-1].falls) if ticks else 0, mean_residual_bw=float(res.mean()),
                           median_residual_bw=float(np.median(res)), contact_fraction=contacts.mean(0),
                           ms_per_tick=1e3 * seconds_per_tick_s)


# ---------------------------------------------------------------------------------------------------
# one ragdoll per controller (the studio session)
# ---------------------------------------------------------------------------------------------------

#: per-tick series a :class:`RagdollTracker` gives per controller (history keys)
SERIES = ("ragdoll_residual_bw", "ragdoll_error_cm", "ragdoll_contact_left", "ragdoll_contact_right",
          "ragdoll_fallen", "ragdoll_falls")


class RagdollTracker:
    """A ragdoll for each controller, each tracking that controller's pose every tick, so the residual
    force, tracking error and foot contacts of MM and LMM compare side by side; ``drawn`` names the one
    the 3D view shows. ``settings`` is shared by all of them (the residual switch acts on the next tick)."""

    def __init__(self, body: Body, dt: float, settings: RagdollSettings | None = None):
        self.body = body
        self.dt = float(dt)
        self.settings = settings if settings is not None else RagdollSettings()
        self.enabled = True
        self.drawn = "mm"
        self.ragdolls: dict[str, Ragdoll] = {}

    def reset(self) -> None:
        """Every ragdoll goes back on its controller's next pose (and its fall count to 0)."""
        self.ragdolls.clear()

    def step(self, snapshots: dict) -> tuple[dict, dict]:
        """Step the ragdoll of every controller in ``snapshots`` (name -> DebugSnapshot) towards its pose;
        returns ``(series, positions)``: ``(name, key) -> value`` for :data:`SERIES` and
        ``name -> (J, 3)`` ragdoll joint positions. Nothing when disabled."""
        if not self.enabled:
            return {}, {}
        series, positions = {}, {}
        for name, snap in snapshots.items():
            ragdoll = self.ragdolls.get(name)
            if ragdoll is None:
                ragdoll = self.ragdolls[name] = Ragdoll(self.body, self.dt, self.settings)
            t = ragdoll.step(snap.pose.global_positions, snap.pose.global_rotations)
            positions[name] = t.positions.astype(np.float32)
            series[(name, "ragdoll_residual_bw")] = t.residual_force_bw if self.settings.residual else np.nan
            series[(name, "ragdoll_error_cm")] = t.tracking_error_cm
            series[(name, "ragdoll_contact_left")] = float(t.foot_contacts[0])
            series[(name, "ragdoll_contact_right")] = float(t.foot_contacts[1])
            series[(name, "ragdoll_fallen")] = float(t.fallen)
            series[(name, "ragdoll_falls")] = float(t.falls)
        return series, positions
