"""Forward kinematics and its inverse: local joint transforms <-> global ones.

The bulk forms work on frames in numpy (the database build, training, analysis): the loop is over
joints (tens), vectorised over everything else (frames), a block of frames at a time for long takes
(:func:`lmm.quat.frame_blocks`). With :mod:`lmm.quat` this is the bottom 'maths' layer; ``lmm.data``
may import it.
"""
from __future__ import annotations

import numpy as np

from lmm import quat


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
    """Global rotations, positions, velocities and angular velocities.

    local_vel / local_angvel are expressed in the parent's frame (as stored in the
    database); global velocities include the contribution of the parent's spin.
    """
    shape = local_pos.shape
    g_rot = np.empty(shape[:-1] + (4,), dtype=local_pos.dtype)
    g_pos = np.empty(shape, dtype=local_pos.dtype)
    g_vel = np.empty(shape, dtype=local_pos.dtype)
    g_ang = np.empty(shape, dtype=local_pos.dtype)
    for j, p in enumerate(parents):
        if p < 0:
            g_rot[..., j, :] = local_rot[..., j, :]
            g_pos[..., j, :] = local_pos[..., j, :]
            g_vel[..., j, :] = local_vel[..., j, :]
            g_ang[..., j, :] = local_angvel[..., j, :]
        else:
            pr = g_rot[..., p, :]
            offset = quat.mul_vec(pr, local_pos[..., j, :])
            g_rot[..., j, :] = quat.mul(pr, local_rot[..., j, :])
            g_pos[..., j, :] = offset + g_pos[..., p, :]
            g_vel[..., j, :] = (g_vel[..., p, :] + quat.mul_vec(pr, local_vel[..., j, :])
                                + np.cross(g_ang[..., p, :], offset))
            g_ang[..., j, :] = quat.mul_vec(pr, local_angvel[..., j, :]) + g_ang[..., p, :]
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
