"""What a pose source hands the character pipeline (:mod:`lmm.character`): one pose in the database's
local form (:class:`SourcePose`) and what a search or projection decided (:class:`SearchOutcome`)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lmm import quat
from lmm.controller import Candidates, LazyField
from lmm.data.derived import cached


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


def root_local_velocities(db):
    """Every frame's root velocity and angular velocity in the root's own frame, (N, 3) each (cached
    beside the database file, see :mod:`lmm.data.derived`)."""
    def compute():
        r = db.rotations[:, 0].astype(np.float64)
        return np.concatenate([quat.inv_mul_vec(r, db.velocities[:, 0].astype(np.float64)),
                               quat.inv_mul_vec(r, db.angular_velocities[:, 0].astype(np.float64))], axis=1)

    both = cached(db, "root_local_velocities", [], compute, random_access=True)  # read a frame at a time
    return both[:, :3], both[:, 3:]
