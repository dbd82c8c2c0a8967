"""Forward kinematics and its inverse: local joint transforms <-> global ones.

The bulk forms work on frames in numpy (the database build, training, analysis): the loop is over
joints (tens), vectorised over everything else (frames), a block of frames at a time for long takes
(:func:`lmm.quat.frame_blocks`). The single-pose forms work on one pose in plain Python floats (the
runtime's per tick: the whole pose, a partial update after IK, one leg). With :mod:`lmm.quat` this is the
bottom 'maths' layer; ``lmm.data`` may import it.
"""
from __future__ import annotations

import numpy as np

from lmm import quat
from lmm.skeleton import subtree


def forward_kinematics(local_rot: np.ndarray, local_pos: np.ndarray, parents) -> tuple[np.ndarray, np.ndarray]:
    """Global rotations and positions from local ones.

    local_rot (..., J, 4), local_pos (..., J, 3); ``parents[j] < j`` (topological order), -1 for roots.
    """
    local_rot, local_pos = np.asarray(local_rot), np.asarray(local_pos)
    g_rot = np.empty(np.broadcast_shapes(local_rot.shape[:-1]) + (4,), dtype=np.result_type(local_rot, local_pos))
    g_pos = np.empty(local_pos.shape, dtype=g_rot.dtype)
    blocks = quat.per_frame_blocks((local_rot, local_pos))
    if blocks is None:
        _forward_kinematics_into(local_rot, local_pos, parents, g_rot, g_pos)
    else:
        for s in blocks:
            _forward_kinematics_block(local_rot[s], local_pos[s], parents, g_rot[s], g_pos[s])
    return g_rot, g_pos


def forward_kinematics_of(local_rot, local_pos, parents, bones, frames, chunk: int = 8192):
    """Global rotations (n, len(bones), 4) and positions (n, len(bones), 3) of ``bones`` only (float64) at
    the frames ``frames`` (indices) of ``local_rot``/``local_pos`` ((N, J, 4)/(N, J, 3), memory-mapped
    ones too): forward kinematics over the bones and their ancestors, not the whole skeleton (the same
    columns of :func:`forward_kinematics` bit for bit, with a fraction of the work and memory)."""
    bones = [int(b) for b in bones]
    needed = set()
    for b in bones:
        while b >= 0 and b not in needed:
            needed.add(b)
            b = int(parents[b])
    chain = sorted(needed)  # parents come before children
    slot = {j: i for i, j in enumerate(chain)}
    sub_parents = np.array([slot[int(parents[j])] if parents[j] >= 0 else -1 for j in chain])
    cols = [slot[b] for b in bones]
    out_rot = np.empty((len(frames), len(bones), 4), dtype=np.float64)
    out_pos = np.empty((len(frames), len(bones), 3), dtype=np.float64)
    # ``chunk`` frames at a time: the intermediates stay in the CPU cache (5x faster at 0.5 M frames than
    # one pass); every frame's arithmetic is the same, so are the results
    for start in range(0, len(frames), chunk):
        part = frames[start:start + chunk]
        rot = np.asarray(local_rot[part])[:, chain].astype(np.float64)
        pos = np.asarray(local_pos[part])[:, chain].astype(np.float64)
        g_rot, g_pos = forward_kinematics(rot, pos, sub_parents)
        out_rot[start:start + len(part)] = g_rot[:, cols]
        out_pos[start:start + len(part)] = g_pos[:, cols]
    return out_rot, out_pos


def _forward_kinematics_block(local_rot, local_pos, parents, g_rot, g_pos) -> None:
    """:func:`_forward_kinematics_into` on a block of frames (B, J, 4) and (B, J, 3), worked in a
    joint-major, component-major copy (:func:`lmm.quat.joint_major`): every operand of every operation is
    then a contiguous row instead of a column strided by a whole frame (about twice as fast on long takes).
    The operations of :func:`lmm.quat.mul` and :func:`lmm.quat.mul_vec` in their order, so the same bits."""
    lr, lp = quat.joint_major(local_rot, g_rot.dtype), quat.joint_major(local_pos, g_rot.dtype)
    gr, gp = np.empty_like(lr), np.empty_like(lp)
    for j, p in enumerate(parents):
        if p < 0:
            gr[j], gp[j] = lr[j], lp[j]
        else:
            quat.mul_rows(gr[p], lr[j], gr[j])
            quat.mul_vec_rows(gr[p], lp[j], gp[j], plus=gp[p])
    g_rot[...] = gr.transpose(2, 0, 1)
    g_pos[...] = gp.transpose(2, 0, 1)


def _forward_kinematics_into(local_rot, local_pos, parents, g_rot, g_pos) -> None:
    for j, p in enumerate(parents):
        if p < 0:
            g_rot[..., j, :] = local_rot[..., j, :]
            g_pos[..., j, :] = local_pos[..., j, :]
        else:
            g_rot[..., j, :] = quat.mul(g_rot[..., p, :], local_rot[..., j, :])
            g_pos[..., j, :] = quat.mul_vec(g_rot[..., p, :], local_pos[..., j, :]) + g_pos[..., p, :]


def forward_kinematics_velocity(local_rot, local_pos, local_vel, local_angvel, parents):
    """Global rotations, positions, velocities and angular velocities (arrays of ``local_pos``'s type).

    local_vel / local_angvel are expressed in the parent's frame (as stored in the
    database); global velocities include the contribution of the parent's spin.
    """
    joints = (np.moveaxis(np.asarray(a), -2, 0) for a in (local_rot, local_pos, local_vel, local_angvel))
    out = forward_kinematics_velocity_joints(*joints, parents, quat.mul, quat.mul_vec, np.cross)
    return tuple(np.stack(x, axis=-2).astype(local_pos.dtype, copy=False) for x in out)


def forward_kinematics_velocity_joints(rot, pos, vel, ang, parents, compose, rotate, cross):
    """The recursion of :func:`forward_kinematics_velocity` in any rotation algebra: ``rot``... per joint
    (indexable by joint), ``compose(a, b)`` the rotation a * b, ``rotate(r, v)`` and ``cross(a, b)``; returns
    four lists, one entry per joint. The numpy form runs it on quaternions, training on torch matrices."""
    g_rot, g_pos, g_vel, g_ang = [], [], [], []
    for j, p in enumerate(parents):
        if p < 0:
            g_rot.append(rot[j])
            g_pos.append(pos[j])
            g_vel.append(vel[j])
            g_ang.append(ang[j])
        else:
            pr = g_rot[p]
            offset = rotate(pr, pos[j])
            g_rot.append(compose(pr, rot[j]))
            g_pos.append(offset + g_pos[p])
            g_vel.append(g_vel[p] + rotate(pr, vel[j]) + cross(g_ang[p], offset))
            g_ang.append(rotate(pr, ang[j]) + g_ang[p])
    return g_rot, g_pos, g_vel, g_ang


def global_to_local(global_rot, global_pos, parents):
    """The inverse of :func:`forward_kinematics`: each joint's rotation and position in its parent's frame."""
    global_rot, global_pos = np.asarray(global_rot), np.asarray(global_pos)
    local_rot = np.array(global_rot, copy=True)
    local_pos = np.array(global_pos, copy=True)
    blocks = quat.per_frame_blocks((global_rot, global_pos))
    if blocks is None:
        for j, p in enumerate(parents):
            if p >= 0:
                local_rot[..., j, :] = quat.inv_mul(global_rot[..., p, :], global_rot[..., j, :])
                local_pos[..., j, :] = quat.inv_mul_vec(global_rot[..., p, :], global_pos[..., j, :] - global_pos[..., p, :])
        return local_rot, local_pos
    for s in blocks:  # long takes: a block of frames at a time, joint-major (the same operations and bits)
        gr, gp = quat.joint_major(global_rot[s], local_rot.dtype), quat.joint_major(global_pos[s], local_pos.dtype)
        lr, lp = gr.copy(), gp.copy()
        for j, p in enumerate(parents):
            if p >= 0:
                w, x, y, z = gr[p]
                inverse = (w, -x, -y, -z)        # conj: a negation is exact
                quat.mul_rows(inverse, gr[j], lr[j])
                quat.mul_vec_rows(inverse, gp[j] - gp[p], lp[j])
        local_rot[s] = lr.transpose(2, 0, 1)
        local_pos[s] = lp.transpose(2, 0, 1)
    return local_rot, local_pos


# ---------------------------------------------------------------------------------------------------
# one pose in plain floats (the runtime's per-tick form): for ~20 bones several times faster than numpy
# calls on tiny arrays. A child's position is summed as parent + offset + w t + u x t
# (:func:`lmm.quat.mul_vec_scalar` with an origin): its own order, not the bulk form's.
# ---------------------------------------------------------------------------------------------------

class PoseSkeleton:
    """A skeleton in the form single-pose forward kinematics reads: ``roots`` (joints without a parent),
    ``links`` ((joint, parent) in index order, a parent before its children) and, per leg chain (hip, knee,
    foot, toe), ``legs[i] = (chain, hip's parent, the rest of the chain's subtree)`` for :func:`leg_update`,
    or ``legs = None`` when the legs do not have the shape it needs (each bone of a chain the parent of the
    next, the legs' subtrees disjoint and the hips' parents outside both)."""
    __slots__ = ("parents", "roots", "links", "leg_chains", "legs", "_subtrees")

    def __init__(self, parents, leg_chains=()):
        self.parents = parents = [int(p) for p in parents]
        self.leg_chains = [tuple(chain) for chain in leg_chains]
        self._subtrees: dict[tuple, tuple] = {}  # solved legs -> (their bones, their subtrees)
        self.roots = [j for j, pj in enumerate(parents) if pj < 0]
        self.links = [(j, pj) for j, pj in enumerate(parents) if pj >= 0]
        subtrees = [subtree(parents, [chain[0]]) for chain in leg_chains]
        inside = [j for sub in subtrees for j in sub]
        ok = len(set(inside)) == len(inside) and all(
            all(parents[b] == a for a, b in zip(chain, chain[1:])) and parents[chain[0]] >= 0
            and parents[chain[0]] not in inside for chain in leg_chains)
        self.legs = [(tuple(chain), parents[chain[0]], [j for j in sub if j not in chain])
                     for chain, sub in zip(leg_chains, subtrees)] if ok else None


def _links_into(g: list, p: list, local_rot, local_pos, links) -> None:
    """Forward kinematics along ``links`` ((joint, parent) pairs, each parent's entry of ``g``/``p`` already
    set), in place: the one loop every single-pose forward kinematics runs."""
    mul, mul_vec = quat.mul_scalar, quat.mul_vec_scalar
    for j, pj in links:
        parent = g[pj]
        g[j] = mul(parent, local_rot[j])
        p[j] = mul_vec(parent, local_pos[j], p[pj])


def pose_forward_kinematics(local_rot, local_pos, skeleton) -> tuple[list, list]:
    """Global rotations and positions of one pose: ``local_rot``/``local_pos`` per joint a 4- and a
    3-sequence of floats (or (J, 4)/(J, 3) arrays), ``skeleton`` a :class:`PoseSkeleton` or a parents
    list. Returns two lists of tuples."""
    if isinstance(local_rot, np.ndarray):
        local_rot, local_pos = local_rot.tolist(), local_pos.tolist()
    if not isinstance(skeleton, PoseSkeleton):
        skeleton = PoseSkeleton(skeleton)
    n = len(local_rot)
    g = [None] * n
    p = [None] * n
    for j in skeleton.roots:
        g[j] = tuple(local_rot[j])
        p[j] = tuple(local_pos[j])
    _links_into(g, p, local_rot, local_pos, skeleton.links)
    return g, p


def pose_forward_kinematics_update(global_rot: list, global_pos: list, local_rot, local_pos, parents,
                                   joints) -> None:
    """:func:`pose_forward_kinematics` recomputed in place only for ``joints`` (a topologically ordered list
    that holds every descendant of each of its joints, see :func:`lmm.skeleton.subtree`); the other joints
    keep their entries. The same float operations per joint, so bit for bit the full pass (after IK only
    the legs change: a few joints instead of the whole skeleton)."""
    links = []
    for j in joints:
        pj = parents[j]
        if pj < 0:
            global_rot[j] = tuple(local_rot[j])
            global_pos[j] = tuple(local_pos[j])
        else:
            links.append((j, pj))
    _links_into(global_rot, global_pos, local_rot, local_pos, links)


def leg_update(global_rot: list, global_pos: list, local_rot: list, local_pos, chain, parent: int, solved) -> None:
    """One leg after IK, in place: the local rotations of ``chain`` (hip, knee, foot, toe; each the parent of
    the next, ``parent`` the hip's parent) from their ``solved`` global rotations (parent^-1 * global, the
    parent's global as solved), then forward kinematics of the chain from the hip's parent (unchanged). The
    hip's global position depends only on bones that did not change: it is kept. The float operations of
    the local-from-global loop and :func:`pose_forward_kinematics_update`, so the same bits."""
    solved_parent = global_rot[parent]   # the parent's global rotation as solved (and kept)
    updated_parent = solved_parent        # the parent's global rotation after the update
    pj = -1                               # the parent of j once past the hip
    for j, q in zip(chain, solved):
        local_rot[j] = local = quat.inv_mul_scalar(solved_parent, q)
        solved_parent = q
        rotation = updated_parent
        updated_parent = global_rot[j] = quat.mul_scalar(rotation, local)
        if pj >= 0:  # (the hip's position, its parent's plus its rotated offset, did not change)
            global_pos[j] = quat.mul_vec_scalar(rotation, local_pos[j], global_pos[pj])
        pj = j


def pose_update_legs(skeleton: PoseSkeleton, global_rot: list, global_pos: list, local_rot: list, local_pos,
                     solved) -> None:
    """One pose after leg IK, in place: ``solved`` lists (leg index, the new global rotations of its chain);
    the chains' local rotations from them, then forward kinematics of the legs' subtrees only. Per leg
    (:func:`leg_update`) when the skeleton's legs allow it, else the generic local-from-global loop and
    :func:`pose_forward_kinematics_update`: the same bits either way."""
    if skeleton.legs is not None:
        for i, rots in solved:
            chain, parent, rest = skeleton.legs[i]
            leg_update(global_rot, global_pos, local_rot, local_pos, chain, parent, rots)
            if rest:
                pose_forward_kinematics_update(global_rot, global_pos, local_rot, local_pos, skeleton.parents, rest)
        return
    parents = skeleton.parents
    for i, rots in solved:
        for j, q in zip(skeleton.leg_chains[i], rots):
            global_rot[j] = q  # the other leg's solve read none of these bones
    key = tuple(i for i, _ in solved)
    found = skeleton._subtrees.get(key)
    if found is None:
        changed = sorted(j for i in key for j in skeleton.leg_chains[i])
        found = skeleton._subtrees[key] = (changed, subtree(parents, changed))
    changed, joints = found
    for j in changed:  # local = parent^-1 * global
        local_rot[j] = quat.inv_mul_scalar(global_rot[parents[j]], global_rot[j])
    pose_forward_kinematics_update(global_rot, global_pos, local_rot, local_pos, parents, joints)
