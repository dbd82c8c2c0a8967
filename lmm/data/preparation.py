"""Preparing motion for the database: the maths between a BVH take and a database range.

Mirroring (left/right swap across the world YZ plane, keeping the original bone offsets), cubic
resampling to the database rate, the simulation (root) bone from the spine and hips, angular velocities
by central differences, and foot contacts from the toes' filtered speed. Pure functions over arrays;
:mod:`lmm.data.build` runs them in the reference pipeline's order. Forward and inverse kinematics:
:mod:`lmm.kinematics`.
"""
from __future__ import annotations

import numpy as np

from lmm import quat
from lmm.data.manifest import Manifest
from lmm.filters import catmull_rom, central_difference, median_filter, savgol_smooth
from lmm.kinematics import forward_kinematics, global_to_local


def mirror_map(names: list[str], pairs) -> np.ndarray:
    """For each joint the index of its left/right counterpart (itself when it has none)."""
    index = {n: i for i, n in enumerate(names)}
    out = np.arange(len(names))
    for i, n in enumerate(names):
        for left, right in pairs:
            for a, b in ((left, right), (right, left)):
                if a in n:
                    j = index.get(n.replace(a, b))
                    if j is not None:
                        out[i] = j
                        break
            if out[i] != i:
                break
    return out


# local-space reflections S a skeleton's left/right offsets may follow (o[mirror] = S o), each with
# the quaternion of the proper rotation M S (M = diag(-1, 1, 1), the world mirror)
_OFFSET_REFLECTIONS = ((np.array([-1.0, 1.0, 1.0]), np.array([1.0, 0.0, 0.0, 0.0])),
                       (np.array([1.0, -1.0, 1.0]), np.array([0.0, 0.0, 0.0, 1.0])),
                       (np.array([1.0, 1.0, -1.0]), np.array([0.0, 0.0, 1.0, 0.0])))


def mirror_frame_rotation(offsets, parents, mirror_idx) -> np.ndarray:
    """The constant rotation C that keeps mirrored local frames those of the original skeleton.

    M R M alone turns every bone offset o into M o, a different skeleton (LAFAN1: legs point along -X),
    so inertializing or blending across mirrored/unmirrored frames would shrink bones through zero.
    With S the reflection relating left and right offsets (o[mirror] ~ S o), M R S = (M R M) (M S)
    gives back the original offsets, so C = M S.
    """
    child = np.asarray(parents) >= 0
    errors = [np.abs(offsets[mirror_idx][child] - s * offsets[child]).sum() for s, _ in _OFFSET_REFLECTIONS]
    return _OFFSET_REFLECTIONS[int(np.argmin(errors))][1]


def mirror_local(local_rot, local_pos, parents, mirror_idx, global_transforms=None):
    """Reflect a motion across the world YZ plane (negate X) and swap left/right joints.

    Bone offsets stay those of the original skeleton (see :func:`mirror_frame_rotation`).
    ``global_transforms``: ``forward_kinematics(local_rot, local_pos, parents)`` when the caller has it.
    """
    g_rot, g_pos = global_transforms or forward_kinematics(local_rot, local_pos, parents)
    g_pos = g_pos * np.array([-1.0, 1.0, 1.0])
    g_rot = g_rot * np.array([1.0, 1.0, -1.0, -1.0])  # M R M with M = diag(-1, 1, 1)
    g_rot = quat.mul(g_rot, mirror_frame_rotation(np.asarray(local_pos)[0], parents, mirror_idx))
    g_rot, g_pos = g_rot[..., mirror_idx, :], g_pos[..., mirror_idx, :]
    return global_to_local(g_rot, g_pos, parents)


def resampled_length(n: int, source_fps: float, target_fps: float, speed_scale: float = 1.0) -> int:
    """How many frames :func:`resample` makes of ``n`` (computed without making them)."""
    step = source_fps * speed_scale / target_fps
    if abs(step - 1.0) < 1e-12:
        return int(n)
    return max(0, int(np.ceil((n - 1 + 1e-9) / step)))


def resample(local_rot, local_pos, source_fps: float, target_fps: float, speed_scale: float = 1.0):
    """Cubic resampling of one contiguous range; ``speed_scale`` > 1 plays the motion faster."""
    n = local_rot.shape[0]
    step = source_fps * speed_scale / target_fps
    if abs(step - 1.0) < 1e-12:
        return local_rot.copy(), local_pos.copy()
    t = np.arange(0.0, n - 1 + 1e-9, step)
    rot = quat.normalize(catmull_rom(quat.unroll(local_rot, axis=0), t))
    pos = catmull_rom(local_pos, t)
    return rot, pos


def simulation_bone(global_rot, global_pos, spine: int, hips: int, hips_forward_axis, manifest: Manifest):
    """Smoothed ground projection of the spine (position) and of the hips' forward axis (facing)."""
    sim_pos = global_pos[:, spine] * np.array([1.0, 0.0, 1.0])
    sim_pos = savgol_smooth(sim_pos, manifest.simulation_position_window, manifest.simulation_order)
    sim_pos[:, 1] = 0.0
    forward = quat.mul_vec(global_rot[:, hips], np.asarray(hips_forward_axis, dtype=np.float64))
    forward = forward * np.array([1.0, 0.0, 1.0])
    forward /= np.maximum(np.linalg.norm(forward, axis=-1, keepdims=True), 1e-8)
    forward = savgol_smooth(forward, manifest.simulation_direction_window, manifest.simulation_order)
    forward[:, 1] = 0.0
    forward /= np.maximum(np.linalg.norm(forward, axis=-1, keepdims=True), 1e-8)
    angle = np.arctan2(forward[:, 0], forward[:, 2])
    sim_rot = quat.from_axis_angle(np.array([0.0, 1.0, 0.0]), angle)
    return sim_rot, sim_pos


def quat_central_difference(q: np.ndarray, dt: float) -> np.ndarray:
    """Angular velocity (rad/s, in the frame q is expressed in) by central differences along axis 0."""
    n = q.shape[0]
    out = np.zeros(q.shape[:-1] + (3,), dtype=np.float64)
    if n < 2:
        return out
    # frame i's difference reads frames i - 1 and i + 1 only: on long takes a block of frames at a time,
    # joint-major (the same operations, the same bits)
    if q.ndim == 3 and n > quat.FRAME_BLOCK:
        for s in quat.frame_blocks(n - 2):
            rows = quat.joint_major(q[2 + s.start:2 + s.stop], q.dtype)   # in q's own type, as in one go
            before = quat.joint_major(q[s], q.dtype)
            out[1 + s.start:1 + s.stop] = _angular_velocity_rows(rows, before, 2 * dt).transpose(2, 0, 1)
    elif n > 2:
        out[1:-1] = quat.to_scaled_angle_axis(quat.abs_(quat.mul_inv(q[2:], q[:-2]))) / (2 * dt)
    out[0] = quat.to_scaled_angle_axis(quat.abs_(quat.mul_inv(q[1], q[0]))) / dt
    out[-1] = quat.to_scaled_angle_axis(quat.abs_(quat.mul_inv(q[-1], q[-2]))) / dt
    return out


def _angular_velocity_rows(a: np.ndarray, b: np.ndarray, dt: float, eps: float = 1e-8) -> np.ndarray:
    """``quat.to_scaled_angle_axis(quat.abs_(quat.mul_inv(a, b))) / dt`` on joint-major component rows
    (J, 4, B): the operations of those functions in their order (conj, product, abs_ twice, the norm's
    sum of squares, arctan2 of the clipped w, the small-angle choice), so the same bits. Returns (J, 3, B)."""
    bw, bx, by, bz = b.transpose(1, 0, 2)
    q = np.empty_like(a)
    quat.mul_rows(a.transpose(1, 0, 2), (bw, -bx, -by, -bz), q.transpose(1, 0, 2))
    w = q[:, 0]
    flip = w < 0.0                                    # abs_ (the second abs_ in log changes nothing)
    np.negative(q, out=q, where=flip[:, None, :])
    xyz = q[:, 1:]
    x, y, z = xyz.transpose(1, 0, 2)
    length = np.sqrt(x * x + y * y + z * z)
    small = length < eps
    safe = np.where(small, 1.0, length)
    halfangle = np.arctan2(length, np.clip(w, -1.0, 1.0))
    out = np.where(small[:, None, :], xyz, (halfangle / safe)[:, None, :] * xyz)
    out *= 2.0
    out /= dt
    return out


def foot_contacts(toe_global_pos: np.ndarray, dt: float, threshold: float, window: int):
    """Contact where the median-filtered toe speed is under the threshold. Returns (contacts, filtered speed)."""
    speed = np.linalg.norm(central_difference(toe_global_pos, dt), axis=-1)
    filtered = median_filter(speed, window)
    return filtered < threshold, filtered
