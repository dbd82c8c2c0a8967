"""Reading a skeletal animation from FBX (binary or ASCII) with the ``ufbx`` bindings (the ``formats`` extra).

How a file becomes BVH's :class:`~lmm.data.bvh.Animation`:

- **Axes and unit:** ufbx converts the scene to Y up, right-handed, centimetres (``target_axes``,
  ``target_unit_meters`` 0.01) whatever the file's own axis and unit settings say, so the result is what the
  shipped BVH takes are (:data:`lmm.data.motion_files.MOTION_UNIT_M`).
- **The skeleton** is every node with a bone attribute or bound to a skin cluster; each one's parent is its
  nearest such ancestor. FBX's pre/post rotations, pivots and inherit modes are applied by ufbx itself: the
  joints' world transforms are evaluated at every frame and turned back into local rotations and translations
  against our parents, so what is drawn is what the file shows. World scale is left out.
- **The motion** is the first animation stack, evaluated at the scene's frame rate
  (``frames_per_second``; 30 fps when it is not 1..1000) from its start to its end time.

A file with no bones, no animation stack or a zero-length one is refused: one line naming the file
(:class:`~lmm.data.motion_files.MotionFileError`).
"""
from __future__ import annotations

import os

import numpy as np

from lmm import kinematics, quat
from lmm.data.bvh import Animation
from lmm.data.motion_files import MOTION_UNIT_M, MotionFileError, depth_first, from_sampled, require_extra
from lmm.data.reading import open_regular

__all__ = ["load", "MAX_SAMPLES", "MAX_FILE_BYTES"]

#: largest file read (ufbx holds the whole scene in memory)
MAX_FILE_BYTES = 512 * 2**20

#: most frames x joints evaluated (the BVH reader's ``MAX_JOINT_FRAMES``)
MAX_SAMPLES = 3_000_000
#: a joint whose local translation moves more than this (centimetres) gets position channels
_MOVES_CM = 1e-6


def _world(node) -> tuple[np.ndarray, np.ndarray]:
    """A node's world rotation (w, x, y, z) and translation, from its ``node_to_world`` matrix."""
    m = node.node_to_world
    cols = np.array([m.c0, m.c1, m.c2], dtype=np.float64).T           # 3x3, columns are the axes
    scale = np.linalg.norm(cols, axis=0)
    return quat.from_matrix(cols / np.where(scale > 0, scale, 1.0)), np.array(m.c3, dtype=np.float64)


def load(path) -> Animation:
    """The first animation stack's skeleton motion in an FBX file (see the module doc)."""
    ufbx = require_extra("ufbx", "reading FBX", "formats", path)
    p = os.fspath(path)
    with open_regular(p, "FBX file") as f:    # a regular file only; OSError for a missing one, as for BVH
        if os.fstat(f.fileno()).st_size > MAX_FILE_BYTES:
            raise MotionFileError(f"the file is larger than {MAX_FILE_BYTES >> 20} MiB", p)
    try:
        scene = ufbx.load_file(p, target_axes=ufbx.axes_right_handed_y_up, target_unit_meters=MOTION_UNIT_M)
    except Exception as e:  # ufbx's own error classes: their message is the reason
        reason = str(e).splitlines()[0][:120] if str(e) else type(e).__name__
        raise MotionFileError(f"not a readable FBX file ({reason})", p) from None
    # ufbx 0.0.5's bindings crash (segfault) when a scene's node list is first read after wrappers of other
    # elements were freed: read every list once, first, and keep the wrappers alive while the scene is used
    nodes = list(scene.nodes)
    clusters = list(scene.skin_clusters)
    bone_nodes = [c.bone_node for c in clusters]
    stacks = list(scene.anim_stacks)
    skinned = {b.typed_id for b in bone_nodes if b is not None}
    joints = {n.typed_id for n in nodes if n.bone is not None or n.typed_id in skinned}
    if not joints:
        raise MotionFileError("has no skeleton (no bones and no skin): only skeletal animations are read", p)
    stack = stacks[0] if stacks else None
    times = [stack.time_begin, stack.time_end] if stack is not None else [0.0, 0.0]
    if not (np.isfinite(times).all() and times[1] > times[0]):
        raise MotionFileError("has no animation (no animation stack with a duration)", p)
    joint_parent = {}
    for j in joints:
        n = nodes[j].parent
        while n is not None and n.typed_id not in joints:
            n = n.parent
        joint_parent[j] = None if n is None else n.typed_id
    order = depth_first(joint_parent, sorted(j for j in joints if joint_parent[j] is None))
    index = {n: k for k, n in enumerate(order)}
    parents = np.array([index[joint_parent[n]] if joint_parent[n] is not None else -1 for n in order])
    names = [nodes[n].name or f"Node_{n}" for n in order]

    fps = float(scene.settings.frames_per_second)
    fps = fps if 1.0 <= fps <= 1000.0 else 30.0          # a rate no frame time of ours can hold: 30 fps
    F = int(round((stack.time_end - stack.time_begin) * fps)) + 1
    if F * len(order) > MAX_SAMPLES:
        raise MotionFileError(f"{F} frames x {len(order)} joints is more than {MAX_SAMPLES} joint-frames", p)
    g_rot = np.empty((F, len(order), 4))
    g_pos = np.empty((F, len(order), 3))
    for f in range(F):
        at = ufbx.evaluate_scene(scene, stack.anim, stack.time_begin + f / fps)
        at_nodes = list(at.nodes)
        for k, n in enumerate(order):
            g_rot[f, k], g_pos[f, k] = _world(at_nodes[n])
    rot, pos = kinematics.global_to_local(g_rot, g_pos, parents)
    moved = [k for k in range(len(order)) if np.ptp(pos[:, k], axis=0).max() > _MOVES_CM]
    return from_sampled(names, parents, pos[0].copy(), rot, pos, moved, fps, p)
