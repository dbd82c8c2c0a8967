"""Is this motion physically possible? Inverse dynamics per frame with ground contact in friction cones.

For a motion of a skeleton (global positions in metres and rotations, ``fps`` frames per second) and its
:class:`lmm.physics.body.Body`:

1. **Velocities and accelerations** by finite differences of the poses' ``qpos`` (MuJoCo's
   ``mj_differentiatePos``, so quaternions difference on the sphere): central differences inside, one-sided
   at the ends.
2. **Inverse dynamics** (``mj_inverse``, contacts and limits switched off) gives the generalized force the
   motion needs; its six rows of the hips' free joint are the external wrench (force, and torque about
   the hips) the whole body needs: joints may push on each other, only the world can push the body.
3. **Ground contact** may supply it only at real contacts: the sole points (bottom corners of the foot and
   toe boxes) lower than ``contact_height_m``, each pushing inside a friction cone linearised as a
   four-sided pyramid (friction ``friction``). The contact forces are the non-negative combination of the
   pyramid edges closest to the needed wrench (non-negative least squares per frame, torque rows in N·m
   against force rows in N, i.e. a lever of 1 m).
4. **Residual**: what contact cannot supply, the "invisible hand": ``residual_force_bw`` (force / body
   weight) and ``residual_torque_bw_m`` (torque / body weight, in metres).

Also per foot and frame: ``penetration_cm`` (how far its lowest sole point is under the floor) and
``sliding_cm_s`` (the horizontal speed of its lowest sole point while it is in contact, else 0).
A character standing still needs 0 residual; one floating in the air needs 1 body weight (gravity).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lmm import quat
from lmm.errors import InputError
from lmm.physics import require_mujoco
from lmm.physics.body import SIDES, Body

DEFAULT_FRICTION = 1.0
DEFAULT_CONTACT_HEIGHT_M = 0.03   # a sole point this close to the floor (or under it) may push on it
TORQUE_LEVER_M = 1.0              # torque rows are divided by this in the least squares


class PlausibilityError(InputError):
    """A motion the plausibility cannot be computed for (too few frames, shapes)."""


@dataclass(eq=False)
class Plausibility:
    """Per-frame physics figures of a motion (arrays of length F, per foot ``(F, 2)``: left, right)."""

    fps: float
    total_mass: float
    residual_force_bw: np.ndarray      # (F,) root residual force / body weight
    residual_torque_bw_m: np.ndarray   # (F,) root residual torque / body weight (m)
    contact_force_bw: np.ndarray       # (F,) total ground force / body weight
    penetration_cm: np.ndarray         # (F, 2) depth of the foot's lowest sole point under the floor
    sliding_cm_s: np.ndarray           # (F, 2) horizontal speed of the lowest sole point in contact, else 0
    contact: np.ndarray                # (F, 2) bool: the foot has a sole point within contact height

    @property
    def n_frames(self) -> int:
        return len(self.residual_force_bw)

    def summary(self, frames=slice(None)) -> dict:
        """Medians, means and peaks over ``frames`` (a slice or index array)."""
        r = self.residual_force_bw[frames]
        t = self.residual_torque_bw_m[frames]
        pen = self.penetration_cm[frames]
        slide = self.sliding_cm_s[frames]
        contact = self.contact[frames]
        if len(r) == 0:
            return {"frames": 0}
        in_contact = slide[contact]
        return {
            "frames": int(len(r)),
            "residual_force_bw_median": float(np.median(r)),
            "residual_force_bw_mean": float(np.mean(r)),
            "residual_force_bw_p95": float(np.percentile(r, 95)),
            "residual_torque_bw_m_median": float(np.median(t)),
            "penetration_cm_max": float(pen.max()),
            "penetration_cm_mean": float(pen.mean()),
            "penetration_frames_fraction": float(np.mean(pen.max(axis=1) > 0.0)),
            "sliding_cm_s_mean_in_contact": float(in_contact.mean()) if in_contact.size else 0.0,
            "sliding_cm_s_p95_in_contact": float(np.percentile(in_contact, 95)) if in_contact.size else 0.0,
            "contact_fraction": [float(contact[:, k].mean()) for k in range(2)],
        }

    def to_dict(self, decimals: int = 4) -> dict:
        """JSON-ready: the per-frame arrays (per-foot arrays as ``{"left": [...], "right": [...]}``) and the
        summary."""
        def arr(a):
            return np.round(np.asarray(a, dtype=np.float64), decimals).tolist()

        def feet(a, cast=arr):
            return {s: cast(a[:, k]) for k, s in enumerate(SIDES)}

        return {
            "fps": self.fps, "frames": self.n_frames, "total_mass_kg": self.total_mass,
            "summary": self.summary(),
            "residual_force_bw": arr(self.residual_force_bw),
            "residual_torque_bw_m": arr(self.residual_torque_bw_m),
            "contact_force_bw": arr(self.contact_force_bw),
            "penetration_cm": feet(self.penetration_cm),
            "sliding_cm_s": feet(self.sliding_cm_s),
            "contact": feet(self.contact, lambda a: [bool(x) for x in a]),
        }


def nnls(A: np.ndarray, b: np.ndarray, tol: float = 1e-10, max_iter: int | None = None) -> np.ndarray:
    """argmin ||A x - b|| subject to x >= 0 (Lawson and Hanson's active-set method); A is (m, n) small."""
    m, n = A.shape
    x = np.zeros(n)
    passive = np.zeros(n, dtype=bool)
    scale = tol * max(1.0, float(np.abs(A).max(initial=0.0)) * float(np.abs(b).max(initial=0.0)))
    w = A.T @ b
    for _ in range(max_iter or 3 * n + 10):
        candidates = np.where(passive, -np.inf, w)
        j = int(np.argmax(candidates))
        if passive.all() or candidates[j] <= scale:
            break
        passive[j] = True
        while True:
            z = np.zeros(n)
            z[passive] = np.linalg.lstsq(A[:, passive], b, rcond=None)[0]
            bad = passive & (z <= 0.0)
            if not bad.any():
                x = z
                break
            alpha = np.min(x[bad] / (x[bad] - z[bad]))
            x = x + alpha * (z - x)
            passive &= x > 1e-12
            x[~passive] = 0.0
        w = A.T @ (b - A @ x)
    return x


def pyramid_edges(friction: float) -> np.ndarray:
    """(4, 3) edges of the linearised friction cone of a floor contact (Y up): normal + friction x tangent."""
    return np.array([[friction, 1.0, 0.0], [-friction, 1.0, 0.0], [0.0, 1.0, friction], [0.0, 1.0, -friction]])


def finite_differences(model, qpos: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(qvel, qacc), each (F, nv), of a ``qpos`` sequence (F, nq) sampled every ``dt`` seconds."""
    mujoco = require_mujoco()
    F = len(qpos)
    nv = model.nv
    half = np.zeros((max(F - 1, 0), nv))
    for t in range(F - 1):
        mujoco.mj_differentiatePos(model, half[t], dt, qpos[t], qpos[t + 1])
    qvel = np.zeros((F, nv))
    qacc = np.zeros((F, nv))
    if F >= 2:
        qvel[0], qvel[-1] = half[0], half[-1]
        qvel[1:-1] = 0.5 * (half[:-1] + half[1:])
    if F >= 3:
        qacc[1:-1] = (half[1:] - half[:-1]) / dt
        qacc[0], qacc[-1] = qacc[1], qacc[-2]
    return qvel, qacc


def root_wrench(body: Body, qpos: np.ndarray, qvel: np.ndarray, qacc: np.ndarray) -> np.ndarray:
    """(F, 6) the external wrench each frame needs, in the world frame: force (N), torque about the hips (N·m)."""
    mujoco = require_mujoco()
    model = body.model
    data = mujoco.MjData(model)
    flags = model.opt.disableflags
    model.opt.disableflags = flags | int(mujoco.mjtDisableBit.mjDSBL_CONTACT) | int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    out = np.empty((len(qpos), 6))
    try:
        for t in range(len(qpos)):
            data.qpos[:] = qpos[t]
            data.qvel[:] = qvel[t]
            data.qacc[:] = qacc[t]
            mujoco.mj_inverse(model, data)
            out[t] = data.qfrc_inverse[:6]
    finally:
        model.opt.disableflags = flags
    # the free joint's rotational rows are in the hips' frame: turn the torque into the world frame
    out[:, 3:] = quat.mul_vec(quat.normalize(qpos[:, 3:7]), out[:, 3:])
    return out


def contact_forces(wrench: np.ndarray, root_pos: np.ndarray, points: np.ndarray, active: np.ndarray,
                   friction: float = DEFAULT_FRICTION) -> tuple[np.ndarray, np.ndarray]:
    """Per frame, the ground wrench closest to ``wrench`` (F, 6) from forces inside friction pyramids at the
    ``active`` (F, P) ``points`` (F, P, 3): returns (supplied wrench (F, 6), total contact force (F, 3))."""
    edges = pyramid_edges(friction)
    supplied = np.zeros_like(wrench)
    force = np.zeros((len(wrench), 3))
    for t in np.flatnonzero(active.any(axis=1)):
        lever = points[t, active[t]] - root_pos[t]                      # (k, 3)
        cols_f = np.broadcast_to(edges, (len(lever), 4, 3)).reshape(-1, 3)
        cols_t = np.cross(np.repeat(lever, 4, axis=0), cols_f) / TORQUE_LEVER_M
        A = np.concatenate([cols_f, cols_t], axis=1).T                 # (6, 4k)
        b = np.concatenate([wrench[t, :3], wrench[t, 3:] / TORQUE_LEVER_M])
        lam = nnls(A, b)
        got = A @ lam
        supplied[t, :3] = got[:3]
        supplied[t, 3:] = got[3:] * TORQUE_LEVER_M
        force[t] = got[:3]
    return supplied, force


def plausibility(body: Body, global_pos, global_rot, fps: float, *, friction: float = DEFAULT_FRICTION,
                 contact_height_m: float = DEFAULT_CONTACT_HEIGHT_M) -> Plausibility:
    """Per-frame residual, penetration and sliding of a motion (see the module doc): ``global_pos``
    (F, J, 3) in metres (Y up, floor y = 0), ``global_rot`` (F, J, 4), ``fps`` frames per second."""
    pos = np.asarray(global_pos, dtype=np.float64)
    rot = np.asarray(global_rot, dtype=np.float64)
    if pos.ndim != 3 or len(pos) < 1:
        raise PlausibilityError(f"positions of shape {pos.shape}: expected (frames, joints, 3)")
    if not (np.isfinite(fps) and fps > 0):
        raise PlausibilityError(f"frame rate {fps}: expected a positive number")
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(rot))):
        raise PlausibilityError("the motion has non-finite positions or rotations")
    dt = 1.0 / fps
    qpos = body.qpos_from_pose(pos, rot)
    qvel, qacc = finite_differences(body.model, qpos, dt)
    wrench = root_wrench(body, qpos, qvel, qacc)

    points = body.sole_points(pos, rot)                                  # (F, P, 3)
    heights = points[..., 1]
    active = heights < contact_height_m
    supplied, force = contact_forces(wrench, pos[:, body.root], points, active, friction)
    residual = wrench - supplied
    weight = body.weight_n

    F = len(pos)
    penetration = np.zeros((F, 2))
    sliding = np.zeros((F, 2))
    contact = np.zeros((F, 2), dtype=bool)
    velocity = np.gradient(points, dt, axis=0) if F > 1 else np.zeros_like(points)
    for k in range(2):
        mine = np.flatnonzero(body.sole_side == k)
        lowest = mine[np.argmin(heights[:, mine], axis=1)]              # (F,) the foot's lowest point
        low_h = heights[np.arange(F), lowest]
        penetration[:, k] = np.maximum(0.0, -low_h) * 100.0
        contact[:, k] = low_h < contact_height_m
        speed = np.linalg.norm(velocity[np.arange(F), lowest][:, [0, 2]], axis=1) * 100.0
        sliding[:, k] = np.where(contact[:, k], speed, 0.0)
    return Plausibility(
        fps=float(fps), total_mass=body.total_mass,
        residual_force_bw=np.linalg.norm(residual[:, :3], axis=1) / weight,
        residual_torque_bw_m=np.linalg.norm(residual[:, 3:], axis=1) / weight,
        contact_force_bw=np.linalg.norm(force, axis=1) / weight,
        penetration_cm=penetration, sliding_cm_s=sliding, contact=contact)
