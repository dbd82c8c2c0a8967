"""A reference BVH drawn beside the characters: its global joint positions in metres, played by time.
The session holds the one that is open (:attr:`app.session.Session.reference`); the 3D view draws it."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np



@dataclass
class ReferenceClip:
    name: str
    parents: np.ndarray
    positions: np.ndarray     # (F, J, 3) metres, first root at the origin (x, z)
    frame_time: float
    names: tuple[str, ...] = ()   # joint names (they size the drawn body parts)

    def at(self, t: float) -> np.ndarray:
        f = int(t / self.frame_time) % len(self.positions)
        return self.positions[f]


def load_reference_clip(path) -> ReferenceClip:
    """A BVH (or glTF, FBX) file as global joint positions in metres (the file's unit guessed from its skeleton's size,
    :func:`lmm.skeleton.guess_unit_scale`).
    Raises ``lmm.data.bvh.BVHError`` / ``OSError`` / ``ValueError`` with a readable message."""
    from lmm.data.motion_files import load_motion
    from lmm.skeleton import guess_unit_scale

    anim = load_motion(path)
    pos = anim.global_positions()
    if pos.ndim != 3 or len(pos) == 0 or pos.shape[1] == 0:
        raise ValueError(f"{path}: no frames to show")
    if not np.isfinite(pos).all():
        raise ValueError(f"{path}: the joint positions are not finite")
    pos = pos * (guess_unit_scale(anim.names, anim.parents, anim.offsets) or 1.0)
    pos = pos - np.array([pos[0, 0, 0], 0.0, pos[0, 0, 2]])
    return ReferenceClip(Path(path).name, anim.parents, pos.astype(np.float32), float(anim.frame_time),
                         tuple(anim.names))
