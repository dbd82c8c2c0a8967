"""An imitation environment around the body: groundwork for a learned physics controller (nothing trains here).

:class:`ImitationEnv` simulates the :class:`lmm.physics.body.Body` of a motion database and asks it to
imitate the database's frames, the setting of adversarial motion priors (AMP) and its conditional
variants:

* **Reset** (:meth:`ImitationEnv.reset`): the body is put in a database frame (pose and finite-difference
  velocity), a random frame of a random range by default, and the episode follows that range.
* **Action** (:meth:`ImitationEnv.step`): PD targets, one rotation vector per ball joint (``3 * (B - 1)``
  numbers, radians) composed onto the reference frame's local rotation; the joints are driven by PD torques
  ``kp * angle_error`` and joint damping ``kd`` (integrated implicitly), both scaled by the mass each
  joint moves, for ``substeps`` physics steps per 60 Hz tick. The root is not
  actuated: the body must balance on its feet.
* **Observation** (:meth:`ImitationEnv.observation`, :attr:`ImitationEnv.observation_size`): the hips'
  height; the world up axis and the hips' linear and angular velocity in the hips' frame; every ball
  joint's local quaternion and angular velocity; the next reference frame's local quaternions.
* **Reward terms** (:data:`REWARD_TERMS`), returned one by one in ``info["reward_terms"]``: the tracking
  terms of DeepMimic (pose, velocity, end effectors, root) are computed; the adversarial terms are named
  with what they would hold and left ``None`` (no discriminator is trained here): ``adversarial`` (AMP:
  ``-log(1 - D(s, s'))`` of a discriminator on state transitions) and ``conditional`` (the same with the
  discriminator conditioned on the controller's goal, e.g. the query's future trajectory).
* **Termination**: a fall (the head below :data:`FALL_HEAD_FRACTION` of the body height) or the range's end.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lmm import quat
from lmm.physics import require_mujoco
from lmm.physics.body import Body, body_for_database

REWARD_TERMS = {
    "pose": "exp(-2 * sum of squared local joint rotation errors (rad^2))",
    "velocity": "exp(-0.1 * sum of squared joint angular velocity errors)",
    "end_effector": "exp(-40 * sum of squared hand and foot position errors relative to the hips (m^2))",
    "root": "exp(-10 * squared hips position error (m^2))",
    "adversarial": "AMP style reward -log(1 - D(s, s')) of a discriminator on transitions (not trained: None)",
    "conditional": "the adversarial term with D conditioned on the goal (not trained: None)",
}
FALL_HEAD_FRACTION = 0.45       # the head below this fraction of the body height is a fall
DEFAULT_KP, DEFAULT_KD = 300.0, 30.0  # N·m/rad, N·m·s/rad, scaled by the body's mass / 70 kg


@dataclass
class StepResult:
    observation: np.ndarray
    reward_terms: dict
    done: bool
    fell: bool


class ImitationEnv:
    """The body of ``db`` imitating its frames; see the module doc. ``tick_s`` is the control interval.
    The environment owns ``body.model`` (it sets its timestep and joint damping): pass a body of its own."""

    def __init__(self, db, body: Body | None = None, tick_s: float = 1.0 / 60.0, substeps: int = 8,
                 kp: float = DEFAULT_KP, kd: float = DEFAULT_KD, seed: int = 0):
        mujoco = require_mujoco("the imitation environment")
        self._mj = mujoco
        self.db = db
        self.body = body or body_for_database(db)
        self.model = self.body.model
        self.model.opt.timestep = tick_s / substeps
        self.data = mujoco.MjData(self.model)
        self.tick_s, self.substeps = tick_s, substeps
        self.rng = np.random.default_rng(seed)
        self.ball = self.body.joints[1:]                           # skeleton joints with a ball joint
        # gains per joint by the mass it moves (a hand's joint moves less than a hip's); the damping is the
        # joint's own (MuJoCo integrates it implicitly, stable for light limbs), the stiffness is applied
        subtree = self.model.body_subtreemass[self.body.body_id[self.ball]] / self.body.total_mass
        gain = np.clip(subtree / 0.5, 0.05, 1.0) * self.body.total_mass / 70.0
        self.kp = kp * gain
        for k, j in enumerate(self.ball):
            self.model.dof_damping[self.body.dof_adr[j]:self.body.dof_adr[j] + 3] = kd * gain[k]
        self.frame = 0
        self.stop = 0
        self._ref_start, self._ref = 0, np.zeros((0, self.model.nq))
        self._ref_data = mujoco.MjData(self.model)
        self._quat_idx = self.body.qpos_adr[self.ball][:, None] + np.arange(4)
        self._dof_idx = self.body.dof_adr[self.ball][:, None] + np.arange(3)
        b = self.body
        self.effectors = [b.key_joints[k] for k in ("left_hand", "right_hand", "left_foot", "right_foot")]

    # -- sizes ------------------------------------------------------------------------------------
    @property
    def action_size(self) -> int:
        return 3 * len(self.ball)

    @property
    def observation_size(self) -> int:
        return 1 + 3 + 3 + 3 + 4 * len(self.ball) + 3 * len(self.ball) + 4 * len(self.ball)

    # -- reference --------------------------------------------------------------------------------
    def reference_qpos(self, frame: int) -> np.ndarray:
        """``qpos`` of database ``frame`` (from the episode's range, computed once at reset)."""
        if self._ref_start <= frame < self._ref_start + len(self._ref):
            return self._ref[frame - self._ref_start]
        rot, pos = self.db.global_transforms(slice(frame, frame + 1))
        return self.body.qpos_from_pose(pos[0], rot[0])

    def reference_qvel(self, frame: int) -> np.ndarray:
        nxt = min(frame + 1, self.stop - 1)
        a, b = (frame - 1, frame) if nxt == frame else (frame, nxt)
        qvel = np.zeros(self.model.nv)
        self._mj.mj_differentiatePos(self.model, qvel, self.tick_s, self.reference_qpos(a), self.reference_qpos(b))
        return qvel

    # -- episode ----------------------------------------------------------------------------------
    def reset(self, frame: int | None = None) -> np.ndarray:
        """Put the body in database ``frame`` (random when None) and return the observation."""
        db = self.db
        if frame is None:
            r = int(self.rng.integers(db.n_ranges))
            start, stop = int(db.range_starts[r]), int(db.range_stops[r])
            frame = int(self.rng.integers(start, max(start + 1, stop - 2)))
        r = int(np.searchsorted(db.range_stops, frame, side="right"))
        r = min(r, db.n_ranges - 1)
        self.frame, self.stop = int(frame), int(db.range_stops[r])
        rot, pos = db.global_transforms(slice(int(db.range_starts[r]), self.stop))
        self._ref_start, self._ref = int(db.range_starts[r]), self.body.qpos_from_pose(pos, rot)
        self._mj.mj_resetData(self.model, self.data)
        self.data.qpos[:] = self.reference_qpos(self.frame)
        rot, pos = self.db.global_transforms(slice(self.frame, self.frame + 1))
        lowest = float(self.body.sole_points(pos[0], rot[0])[:, 1].min())
        self.data.qpos[1] += max(0.0, -lowest)                     # soles out of the floor
        self.data.qvel[:] = self.reference_qvel(self.frame)
        self._mj.mj_forward(self.model, self.data)
        return self.observation()

    def observation(self) -> np.ndarray:
        d, b = self.data, self.body
        root_q = d.qpos[3:7]
        up = quat.inv_mul_vec(root_q, np.array([0.0, 1.0, 0.0]))
        lin = quat.inv_mul_vec(root_q, d.qvel[0:3])
        joints_q = np.concatenate([d.qpos[b.qpos_adr[j]:b.qpos_adr[j] + 4] for j in self.ball])
        joints_v = np.concatenate([d.qvel[b.dof_adr[j]:b.dof_adr[j] + 3] for j in self.ball])
        ref = self.reference_qpos(min(self.frame + 1, self.stop - 1))
        ref_q = np.concatenate([ref[b.qpos_adr[j]:b.qpos_adr[j] + 4] for j in self.ball])
        return np.concatenate([[d.qpos[1]], up, lin, d.qvel[3:6], joints_q, joints_v, ref_q])

    def step(self, action) -> StepResult:
        """One control tick: PD towards the reference frame's rotations composed with ``action``."""
        action = np.asarray(action, dtype=np.float64).reshape(len(self.ball), 3)
        b, d, m = self.body, self.data, self.model
        self.frame = min(self.frame + 1, self.stop - 1)
        ref = self.reference_qpos(self.frame)
        qa = self._quat_idx                                        # (B-1, 4) qpos indices of the ball joints
        targets = quat.mul(ref[qa], quat.from_scaled_angle_axis(action))
        for _ in range(self.substeps):
            err = quat.to_scaled_angle_axis(quat.abs_(quat.inv_mul(d.qpos[qa], targets)))   # joint frames
            d.qfrc_applied[:] = 0.0
            d.qfrc_applied[self._dof_idx] = self.kp[:, None] * err
            self._mj.mj_step(m, d)
        terms = self.reward_terms(ref)
        head_y = d.xpos[b.body_id[b.key_joints["head"]], 1]
        fell = bool(head_y < FALL_HEAD_FRACTION * b.height_m) or not np.all(np.isfinite(d.qpos))
        return StepResult(self.observation(), terms, fell or self.frame >= self.stop - 1, fell)

    def reward_terms(self, ref_qpos: np.ndarray) -> dict:
        """The terms of :data:`REWARD_TERMS` for the current state against ``ref_qpos``."""
        b, d, m = self.body, self.data, self.model
        pose_err = 0.0
        for j in self.ball:
            a = b.qpos_adr[j]
            pose_err += float(np.sum(quat.to_scaled_angle_axis(quat.abs_(quat.inv_mul(d.qpos[a:a + 4], ref_qpos[a:a + 4]))) ** 2))
        ref_data = self._ref_data
        ref_data.qpos[:] = ref_qpos
        self._mj.mj_kinematics(m, ref_data)
        root = b.body_id[b.root]
        eff = b.body_id[self.effectors]
        sim_rel = d.xpos[eff] - d.xpos[root]
        ref_rel = ref_data.xpos[eff] - ref_data.xpos[root]
        ref_vel = self.reference_qvel(self.frame)
        vel_err = float(np.sum((d.qvel[6:] - ref_vel[6:]) ** 2))
        return {
            "pose": float(np.exp(-2.0 * pose_err)),
            "velocity": float(np.exp(-0.1 * vel_err)),
            "end_effector": float(np.exp(-40.0 * np.sum((sim_rel - ref_rel) ** 2))),
            "root": float(np.exp(-10.0 * np.sum((d.xpos[root] - ref_data.xpos[root]) ** 2))),
            "adversarial": None,
            "conditional": None,
        }
