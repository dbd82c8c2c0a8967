"""Pose windows for motion search by example: the one representation every embedding reads.

A take of any skeleton is reduced to six **key joints** matched by name (:func:`match_key_joints`):
hips, head, both hands and both feet. Each frame becomes :data:`FRAME_DIM` numbers that do not depend
on where the character stands, which way it faces or how tall it is (:func:`frame_features`):

* the head, hands and feet relative to the hips, on the ground plane rotated so the hips face +Z,
  divided by the take's standing hips height (15 values);
* the hips height over that same reference (1 value);
* the hips' horizontal velocity in that heading frame, in reference heights per second, and the yaw
  rate in radians per second (3 values).

Frames are resampled to :data:`WINDOW_FPS` (linear interpolation on the take's own time axis), and a
**window** is :data:`WINDOW_FRAMES` consecutive resampled frames, ``(WINDOW_FRAMES, FRAME_DIM)``.
Windows start at every resampled frame; :func:`window_start_frames` maps them back to the file's own
frame numbers. :func:`mirror_frames` swaps left and right (the augmentation and the mirrored queries).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lmm.errors import InputError
from lmm.skeleton import KEY_ROLES, SkeletonMatchError, match_roles  # noqa: F401  (SkeletonMatchError re-exported)

KEY_JOINTS = KEY_ROLES
LIMB_JOINTS = KEY_JOINTS[1:]            # relative to the hips, in this order
WINDOW_FPS = 30.0
WINDOW_FRAMES = 32                      # 1.07 s: a step cycle of a walk, two of a run
FRAME_DIM = 3 * len(LIMB_JOINTS) + 1 + 3
MIRROR_PERMUTATION = (0, 2, 1, 4, 3)    # head, hands and feet with left and right swapped
# a frame time written rounded (LAFAN1: 0.033333 s, 30.0003 fps) is the target rate: resampling it would
# drop a frame from every 60-frame query and shift every later frame by a fraction of one
SAME_RATE_TOLERANCE = 1e-4


def match_key_joints(names, path="") -> dict[str, int]:
    """Joint index of each key joint, matched by name (:func:`lmm.skeleton.match_roles`: exact normalized
    synonyms, e.g. ``LeftHand``, ``mixamorig:LeftHand``, ``l_wrist``). Raises :class:`SkeletonMatchError`
    naming ``path`` and every key joint it could not find."""
    return match_roles(names, KEY_JOINTS, path)


def reference_height(hips_y: np.ndarray) -> float:
    """The take's standing hips height (its 90th percentile), the unit of every position: a crouch or a
    fall does not change it, and takes of tall and short people (or cm and m) compare."""
    h = float(np.percentile(hips_y, 90)) if len(hips_y) else 0.0
    return h if h > 1e-6 else 1.0


def frame_features(key_positions: np.ndarray, fps: float, ref_height: float | None = None) -> np.ndarray:
    """``(F, FRAME_DIM)`` float32 features of ``(F, 6, 3)`` key-joint world positions (Y up, any unit)
    sampled at ``fps``, in :data:`KEY_JOINTS` order (see the module doc)."""
    p = np.asarray(key_positions, dtype=np.float64)
    F = p.shape[0]
    hips = p[:, 0]
    ref = reference_height(hips[:, 1]) if ref_height is None else float(ref_height)
    # heading: the direction from the right to the left hand/foot pair, turned a quarter to face forward
    across = (p[:, 2] - p[:, 3]) + (p[:, 4] - p[:, 5])
    yaw = np.arctan2(-across[:, 2], across[:, 0]) if F else np.zeros(0)  # forward = across x up
    yaw = np.unwrap(_smooth(yaw, 5)) if F else yaw
    c, s = np.cos(yaw), np.sin(yaw)
    rel = p[:, 1:] - hips[:, None, :]
    local = np.empty_like(rel)
    # rotate by -yaw about Y so the heading becomes +Z
    local[..., 0] = c[:, None] * rel[..., 0] - s[:, None] * rel[..., 2]
    local[..., 1] = rel[..., 1]
    local[..., 2] = s[:, None] * rel[..., 0] + c[:, None] * rel[..., 2]
    vel = np.gradient(hips, axis=0) * fps if F > 1 else np.zeros_like(hips)
    vx = c * vel[:, 0] - s * vel[:, 2]
    vz = s * vel[:, 0] + c * vel[:, 2]
    yaw_rate = np.gradient(yaw) * fps if F > 1 else np.zeros(F)
    out = np.concatenate([local.reshape(F, -1) / ref, (hips[:, 1] / ref)[:, None],
                          np.stack([vx / ref, vz / ref, yaw_rate], axis=1)], axis=1)
    return out.astype(np.float32)


def _smooth(x: np.ndarray, width: int) -> np.ndarray:
    """A centred moving average of an angle (on its unit vector) over ``width`` frames."""
    if len(x) < width:
        return x
    k = np.ones(width) / width
    cs = np.convolve(np.cos(x), k, mode="same"), np.convolve(np.sin(x), k, mode="same")
    return np.arctan2(cs[1], cs[0])


def frame_ratio(fps: float, target_fps: float = WINDOW_FPS) -> float:
    """File frames per resampled frame: ``fps / target_fps``, exactly 1 within :data:`SAME_RATE_TOLERANCE`."""
    r = float(fps) / float(target_fps)
    return 1.0 if abs(r - 1.0) < SAME_RATE_TOLERANCE else r


def resample(features: np.ndarray, fps: float, target_fps: float = WINDOW_FPS) -> np.ndarray:
    """Frames at ``fps`` -> frames at ``target_fps`` by linear interpolation (time 0 kept); unchanged when
    the rates differ by less than :data:`SAME_RATE_TOLERANCE` (relative)."""
    F = len(features)
    if F == 0 or abs(fps / target_fps - 1.0) < SAME_RATE_TOLERANCE:
        return np.asarray(features, np.float32)
    n = int(math.floor((F - 1) * target_fps / fps)) + 1
    t = np.arange(n) * (fps / target_fps)
    i0 = np.minimum(np.floor(t).astype(int), F - 1)
    i1 = np.minimum(i0 + 1, F - 1)
    w = (t - i0)[:, None]
    return ((1.0 - w) * features[i0] + w * features[i1]).astype(np.float32)


def windows(frames: np.ndarray, length: int = WINDOW_FRAMES, stride: int = 1) -> np.ndarray:
    """``(n, length, FRAME_DIM)`` view of every window of ``length`` resampled frames (start 0, stride,
    2 stride...); empty when the take is shorter than one window."""
    frames = np.ascontiguousarray(frames, dtype=np.float32)
    if len(frames) < length:
        return np.zeros((0, length, frames.shape[1] if frames.ndim == 2 else FRAME_DIM), np.float32)
    view = np.lib.stride_tricks.sliding_window_view(frames, length, axis=0)  # (n, D, length)
    return np.swapaxes(view, 1, 2)[::stride]


def window_start_frames(starts: np.ndarray, file_fps: float, target_fps: float = WINDOW_FPS) -> np.ndarray:
    """Resampled window starts -> the file's own frame numbers (rounded)."""
    return np.rint(np.asarray(starts) * frame_ratio(file_fps, target_fps)).astype(np.int64)


def mirror_frames(frames: np.ndarray) -> np.ndarray:
    """Left and right swapped (x negated in the heading frame, yaw rate negated): the features of the
    mirrored motion."""
    f = np.array(frames, dtype=np.float32, copy=True)
    limbs = f[..., : 3 * len(LIMB_JOINTS)].reshape(*f.shape[:-1], len(LIMB_JOINTS), 3)
    limbs = limbs[..., list(MIRROR_PERMUTATION), :]
    limbs[..., 0] *= -1.0
    f[..., : 3 * len(LIMB_JOINTS)] = limbs.reshape(*f.shape[:-1], -1)
    f[..., -3] *= -1.0   # sideways velocity
    f[..., -1] *= -1.0   # yaw rate
    return f


@dataclass
class TakeFrames:
    """One file reduced to resampled key-joint frames."""
    path: str
    file_fps: float
    n_file_frames: int
    frames: np.ndarray      # (n, FRAME_DIM) at WINDOW_FPS

    def file_frame(self, resampled: int) -> int:
        return int(round(resampled * frame_ratio(self.file_fps)))


def take_frames(anim, path: str = "", frames: tuple[int, int] | None = None) -> TakeFrames:
    """Key-joint frames of a loaded :class:`lmm.data.bvh.Animation` (optionally only file frames
    ``[a, b)``), resampled to :data:`WINDOW_FPS`."""
    keys = match_key_joints(anim.names, path)
    g = anim.global_positions()
    n = anim.n_frames
    a, b = (0, n) if frames is None else frames
    if not (0 <= a < b <= n):
        raise InputError(f"{path}: frames {a}:{b} are not a non-empty range inside the take's 0:{n}")
    ref = reference_height(g[:, keys["hips"], 1])
    kp = g[a:b][:, [keys[k] for k in KEY_JOINTS]]
    fps = 1.0 / anim.frame_time
    return TakeFrames(path, fps, b - a, resample(frame_features(kp, fps, ref), fps))
