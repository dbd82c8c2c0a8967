"""How far apart two motions of the same skeleton are, after dynamic time warping.

``compare(A, B)`` aligns the frames of two motions by DTW on their rotations and reports, along the
alignment path:

* **rotation error**: per joint the geodesic angle ``2 acos |<q_a, q_b>|`` of ``q_a^-1 q_b`` (radians),
  averaged over joints and aligned frame pairs. Joints are compared by their local rotations, except the
  first (the hips), whose rotation is its global one with the facing removed: where the character
  stands and faces is the root path's business, not the pose's;
* **position error** (cm): the mean distance of matching joints, root-relative (each pose in its hips'
  heading frame) and in the world; the world error of :func:`compare_files` is by default taken with B
  moved rigidly so that the first aligned frames stand at the same ground position and facing (a run
  started elsewhere than its source take is not far from it for that reason alone);
* per-frame errors of A (over its aligned pairs), for plots over time.

The DTW is the textbook one (steps right, down, diagonal; value = the smallest sum of frame costs over a
path from the first pair to the last) inside a Sakoe-Chiba band of half-width ``window`` frames, widened
by the length difference so that motions of different lengths always have a path. Each row of the
accumulated cost is one numpy step: with ``S`` the running sum of the row's costs,
``acc[j] = S[j] + min_{k <= j} (t[k] - S[k])`` where ``t`` takes the best of the diagonal and upper
neighbours, which is the row's left-neighbour recurrence solved in closed form.

Skeletons match when their joint names are equal after dropping a leading root joint that only one of
them has (a recording's simulation bone); anything else is a one-line :class:`CompareError`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lmm import quat
from lmm.errors import InputError
from lmm.skeleton import SIMULATION_BONE_NAMES



class CompareError(InputError):
    """Two motions that cannot be compared (skeletons, empty ranges); the message names the files."""


def band_bounds(n: int, m: int, window: int | None) -> tuple[np.ndarray, np.ndarray]:
    """Per row ``i`` of an ``n x m`` DTW grid the columns ``[lo[i], hi[i])`` inside the Sakoe-Chiba band of
    half-width ``window`` (None: no band), widened by the length difference."""
    i = np.arange(n)
    if window is None:
        return np.zeros(n, np.int64), np.full(n, m, np.int64)
    w = max(1, int(window))
    lo = np.maximum(i - max(0, n - m) - w + 1, 0)
    hi = np.minimum(i + max(0, m - n) + w, m)
    return lo.astype(np.int64), hi.astype(np.int64)


def dtw_align(row_cost, n: int, m: int, window: int | None = None) -> tuple[float, np.ndarray]:
    """DTW over an ``n x m`` grid whose costs come a row at a time: ``row_cost(i, lo, hi)`` returns the
    costs of cells ``(i, lo..hi-1)``. Returns the DTW value (smallest path sum) and the path ``(k, 2)``
    of aligned index pairs from ``(0, 0)`` to ``(n - 1, m - 1)``."""
    if n == 0 or m == 0:
        raise ValueError("DTW of an empty sequence")
    lo, hi = band_bounds(n, m, window)
    rows: list[np.ndarray] = []
    prev = None
    for i in range(n):
        a, b = int(lo[i]), int(hi[i])
        c = np.asarray(row_cost(i, a, b), np.float64)
        if i == 0:
            acc = np.cumsum(c)                                    # only the left neighbour on the first row
        else:
            pa, pb = int(lo[i - 1]), int(hi[i - 1])
            up = np.full(b - a, np.inf)
            diag = np.full(b - a, np.inf)
            js = np.arange(a, b)
            inside = (js >= pa) & (js < pb)
            up[inside] = prev[js[inside] - pa]
            dj = js - 1
            inside_d = (dj >= pa) & (dj < pb)
            diag[inside_d] = prev[dj[inside_d] - pa]
            t = c + np.minimum(up, diag)
            s = np.cumsum(c)
            with np.errstate(invalid="ignore"):
                acc = s + np.minimum.accumulate(t - s)
            acc = np.where(np.isfinite(acc), acc, np.inf)
        rows.append(acc)
        prev = acc
    total = float(rows[-1][m - 1 - int(lo[-1])])
    # backtrack: the cheapest predecessor (diagonal first on ties)
    path = [(n - 1, m - 1)]
    i, j = n - 1, m - 1
    get = lambda r, col: rows[r][col - lo[r]] if lo[r] <= col < hi[r] else np.inf  # noqa: E731
    while i > 0 or j > 0:
        options = [(get(i - 1, j - 1) if i > 0 and j > 0 else np.inf, i - 1, j - 1),
                   (get(i - 1, j) if i > 0 else np.inf, i - 1, j),
                   (get(i, j - 1) if j > 0 else np.inf, i, j - 1)]
        _, i, j = min(options, key=lambda o: o[0])
        path.append((i, j))
    return total, np.array(path[::-1], dtype=np.int64)


def dtw_reference(cost: np.ndarray, window: int | None = None) -> float:
    """The plain double loop over a full cost matrix (for tests)."""
    n, m = cost.shape
    lo, hi = band_bounds(n, m, window)
    acc = np.full((n + 1, m + 1), np.inf)
    acc[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            if lo[i - 1] <= j - 1 < hi[i - 1]:
                acc[i, j] = cost[i - 1, j - 1] + min(acc[i - 1, j - 1], acc[i - 1, j], acc[i, j - 1])
    return float(acc[n, m])


# ---------------------------------------------------------------------------------------------------
# poses
# ---------------------------------------------------------------------------------------------------

@dataclass
class Motion:
    """What the comparison needs of one motion: joint names, rotations used for the rotation error
    ``(F, J, 4)``, world positions ``(F, J, 3)`` in cm and root-relative positions ``(F, J, 3)`` in cm."""
    name: str
    joints: list[str]
    rotations: np.ndarray
    world_cm: np.ndarray
    local_cm: np.ndarray
    fps: float
    heading: np.ndarray | None = None   # (F, 4) the hips' facing (yaw), for aligning two motions' starts


def _heading(q_hips: np.ndarray, forward_axis) -> np.ndarray:
    """Yaw rotations ``(..., 4)`` of the hips' forward axis projected on the ground."""
    f = quat.mul_vec(q_hips, np.asarray(forward_axis, np.float64))
    return quat.from_axis_angle(np.array([0.0, 1.0, 0.0]), np.arctan2(f[..., 0], f[..., 2]))


def motion_from_animation(anim, name: str, cm_per_unit: float = 1.0, frames=None,
                          hips_forward_axis=(0.0, 0.0, 1.0)) -> Motion:
    """A :class:`Motion` of a loaded BVH (optionally file frames ``[a, b)``), without a leading simulation
    bone. ``cm_per_unit``: centimetres per file unit (LAFAN1 and our recordings: 1)."""
    n = anim.n_frames
    a, b = (0, n) if frames is None else frames
    if not (0 <= a < b <= n):
        raise CompareError(f"{name}: frames {a}:{b} are not a non-empty range inside the motion's 0:{n}")
    g_rot, g_pos = anim.global_transforms()
    return motion_from_arrays(name, list(anim.names), anim.local_rotations()[a:b], g_rot[a:b],
                              g_pos[a:b] * cm_per_unit, 1.0 / anim.frame_time, hips_forward_axis)


def motion_from_arrays(name: str, names: list[str], local_rot, global_rot, global_pos_cm, fps: float,
                       hips_forward_axis=(0.0, 0.0, 1.0)) -> Motion:
    """A :class:`Motion` from per-frame arrays ``(F, J, ...)`` of one skeleton (a leading simulation bone
    is dropped), e.g. a controller's poses collected in memory."""
    first = 1 if (names[0] in SIMULATION_BONE_NAMES and len(names) > 1) else 0
    keep = slice(first, None)
    g_rot = np.asarray(global_rot, np.float64)[:, keep]
    g_pos = np.asarray(global_pos_cm, np.float64)[:, keep]
    rot, heading = error_rotations(np.asarray(local_rot, np.float64)[:, keep], g_rot, hips_forward_axis)
    rel = g_pos - g_pos[:, :1] * np.array([1.0, 0.0, 1.0])
    local = quat.inv_mul_vec(heading[:, None, :], rel)
    return Motion(name, list(names[first:]), rot, g_pos, local, float(fps), heading)


def error_rotations(local_rot: np.ndarray, global_rot: np.ndarray, hips_forward_axis=(0.0, 0.0, 1.0)):
    """The rotations the rotation error compares, ``(..., J, 4)``, of poses whose first joint is the hips
    (no simulation bone): the local rotations, with the hips' one replaced by its global rotation without
    the facing; and the facing ``(..., 4)``."""
    heading = _heading(global_rot[..., 0, :], hips_forward_axis)
    rot = np.array(local_rot, np.float64)
    rot[..., 0, :] = quat.normalize(quat.inv_mul(heading, global_rot[..., 0, :]))   # hips without the facing
    return quat.normalize(rot), heading


def rotation_cost_rows(a: Motion, b: Motion):
    """``row_cost(i, lo, hi)``: mean joint geodesic angle between frame ``i`` of A and frames lo..hi-1 of B."""
    qa, qb = a.rotations, b.rotations

    def row(i, lo, hi):
        # 2 acos |<qa, qb>|: one dot product per joint (the errors reported along the path use the
        # exact form, :func:`geodesic`)
        d = np.abs(np.einsum("jk,fjk->fj", qa[i], qb[lo:hi]))
        return (2.0 * np.arccos(np.minimum(d, 1.0))).mean(axis=1)
    return row


def geodesic(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    """Angle (radians) of ``qa^-1 qb`` per quaternion pair, ``2 atan2(|xyz|, |w|)``: exactly 0 for equal
    rotations (``acos`` of a rounded dot product is not) and accurate for small angles."""
    r = quat.inv_mul(qa, qb)
    return 2.0 * np.arctan2(np.linalg.norm(r[..., 1:], axis=-1), np.abs(r[..., 0]))


def resample_motion(x: Motion, fps: float) -> Motion:
    """``x`` at ``fps`` by nearest-frame resampling (the same duration)."""
    if abs(x.fps - fps) <= 1e-6 * fps:
        return x
    n = len(x.rotations)
    count = max(int(math.floor((n - 1) * fps / x.fps + 1e-9)) + 1, 1)
    idx = np.minimum(np.rint(np.arange(count) * (x.fps / fps)).astype(np.int64), n - 1)
    heading = None if x.heading is None else x.heading[idx]
    return Motion(x.name, x.joints, x.rotations[idx], x.world_cm[idx], x.local_cm[idx], fps, heading)


def world_aligned_at_start(a: Motion, b: Motion, ia: int = 0, ib: int = 0) -> np.ndarray:
    """B's world positions ``(F, J, 3)`` moved rigidly (a turn about the vertical and a shift on the ground)
    so that its frame ``ib``'s hips stand on the ground where A's frame ``ia``'s do, facing the same way."""
    if a.heading is None or b.heading is None:
        raise ValueError("aligning needs both motions' headings (motion_from_arrays gives them)")
    yaw = quat.mul_inv(a.heading[ia], b.heading[ib])
    ground = np.array([1.0, 0.0, 1.0])
    return quat.mul_vec(yaw, b.world_cm - b.world_cm[ib, 0] * ground) + a.world_cm[ia, 0] * ground


def compare_motions(a: Motion, b: Motion, window: int | None = None, align_start: bool = False) -> dict:
    """DTW-aligned errors of B against A (see the module doc). ``window``: the Sakoe-Chiba half-width in
    frames (default: a tenth of the longer motion, at least 10 frames). ``align_start``: the world error
    with B moved so that the first aligned pair stands at the same ground position and facing
    (:func:`world_aligned_at_start`)."""
    if a.joints != b.joints:
        only_a = [j for j in a.joints if j not in b.joints][:4]
        only_b = [j for j in b.joints if j not in a.joints][:4]
        raise CompareError(f"{a.name} and {b.name} have different skeletons ({len(a.joints)} and {len(b.joints)} "
                           f"joints; only in the first: {', '.join(only_a) or '-'}; only in the second: "
                           f"{', '.join(only_b) or '-'})")
    resampled = None
    if abs(a.fps - b.fps) > 1e-6 * max(a.fps, b.fps):   # compare at the lower frame rate (nearest frames)
        resampled = min(a.fps, b.fps)
        a, b = resample_motion(a, resampled), resample_motion(b, resampled)
    n, m = len(a.rotations), len(b.rotations)
    if window is None:
        window = max(10, int(math.ceil(0.1 * max(n, m))))
    total, path = dtw_align(rotation_cost_rows(a, b), n, m, window)
    ia, ib = path[:, 0], path[:, 1]
    rot = geodesic(a.rotations[ia], b.rotations[ib]).mean(axis=1)
    local = np.linalg.norm(a.local_cm[ia] - b.local_cm[ib], axis=2).mean(axis=1)
    b_world = world_aligned_at_start(a, b, ia[0], ib[0]) if align_start else b.world_cm
    world = np.linalg.norm(a.world_cm[ia] - b_world[ib], axis=2).mean(axis=1)
    per_frame = lambda x: np.bincount(ia, weights=x, minlength=n) / np.maximum(np.bincount(ia, minlength=n), 1)  # noqa: E731
    return {
        "a": a.name, "b": b.name, "frames": [n, m], "fps": a.fps, "resampled_to_fps": resampled,
        "joints": len(a.joints), "window": int(window),
        "dtw_value": total,
        "rotation_error_rad": float(rot.mean()),
        "position_error_cm": {"root_relative": float(local.mean()), "world": float(world.mean())},
        "world_aligned_at_start": bool(align_start),
        "per_frame": {"rotation_error_rad": per_frame(rot).tolist(),
                      "root_relative_cm": per_frame(local).tolist(), "world_cm": per_frame(world).tolist()},
        "path": path.tolist(),
    }


def compare_files(path_a, path_b, frames_a=None, frames_b=None, window: int | None = None,
                  cm_per_unit: float = 1.0, hips_forward_axis=None, align_start: bool = True) -> dict:
    """Load two BVH files and compare them (one-line errors name the files). ``hips_forward_axis``: the
    hips' local forward axis (default: the shipped manifest's, LAFAN1's skeleton). ``align_start``: see
    :func:`compare_motions` (on by default here: two files rarely start at the same place)."""
    from lmm.data.motion_files import load_motion

    if hips_forward_axis is None:
        from lmm import DEFAULT_MANIFEST
        from lmm.data.manifest import load_manifest
        hips_forward_axis = load_manifest(DEFAULT_MANIFEST).hips_forward_axis
    motions = []
    for path, frames in ((path_a, frames_a), (path_b, frames_b)):
        anim = load_motion(path)
        motions.append(motion_from_animation(anim, str(path), cm_per_unit, frames, hips_forward_axis))
    return compare_motions(*motions, window=window, align_start=align_start)
