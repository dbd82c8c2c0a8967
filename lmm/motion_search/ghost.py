"""A search result as a pose sequence to show beside the character (the studio's preview ghosts).

:func:`segment_positions` turns file frames ``[start, end)`` of any BVH take into global joint positions
in the ghost's own frame: the hips of the first frame above the origin, facing +Z (the heading of
:mod:`lmm.motion_search.windows`, from the hands and feet), scaled so that the take's standing hips height
becomes ``hips_height`` (the character's, in metres): a take in centimetres, inches or of a child shows
at the character's size.
"""
from __future__ import annotations

import numpy as np

from lmm.motion_search.windows import KEY_JOINTS, match_key_joints, reference_height


def heading_yaw(key_positions: np.ndarray) -> float:
    """Yaw (radians about +Y) of the facing of ``(F, 6, 3)`` key-joint positions, averaged over the frames."""
    p = np.asarray(key_positions, np.float64)
    across = ((p[:, 2] - p[:, 3]) + (p[:, 4] - p[:, 5])).mean(axis=0)
    return float(np.arctan2(-across[2], across[0]))


def segment_positions(anim, start: int, end: int, hips_height: float = 1.0, path: str = "") -> np.ndarray:
    """``(end - start, J, 3)`` float32 global positions of file frames ``[start, end)`` of ``anim``, in the
    ghost's frame (see the module doc)."""
    keys = match_key_joints(anim.names, path or anim.path or "")
    g = anim.global_positions()
    start, end = max(0, int(start)), min(int(end), anim.n_frames)
    scale = float(hips_height) / reference_height(g[:, keys["hips"], 1])
    seg = g[start:end]
    key = seg[: min(5, len(seg))][:, [keys[k] for k in KEY_JOINTS]]
    yaw = heading_yaw(key)
    c, s = np.cos(yaw), np.sin(yaw)
    origin = seg[0, keys["hips"]].copy()
    origin[1] = 0.0
    rel = seg - origin
    out = np.empty_like(rel)
    out[..., 0] = c * rel[..., 0] - s * rel[..., 2]
    out[..., 1] = rel[..., 1]
    out[..., 2] = s * rel[..., 0] + c * rel[..., 2]
    return (out * scale).astype(np.float32)
