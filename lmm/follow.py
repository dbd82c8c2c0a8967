"""Following a reference take: its derived input drives the controllers from a reset, the take is moved
to start where they start, and every tick each controller's pose is judged against the take.

* **Input**: :func:`lmm.input_from_motion.derive_input` of the take's root path (the manifest's simulation
  bone), one row per tick, as an :class:`lmm.data.inputs.InputLog` that is replayed like a recorded one.
* **Alignment**: the take moved and turned so its root path starts at the origin facing +Z
  (:func:`lmm.input_from_motion.aligned`), as a controller starts after a reset; tick ``k`` (time
  ``k dt``) corresponds to the take's time ``k dt`` from the start of the range.
* **Aligned frame and pose error** (:class:`FrameTracker`): a controller does not hit the take's timing
  exactly (a search picks a step a little early or late), so the take's frame at the tick's time is
  refined by a small search: the frames within ``search_s`` of it, and never before the frame this
  controller was aligned with on the previous tick (monotone, like a DTW path), the one whose pose is
  nearest. The error is :mod:`lmm.compare`'s rotation error of that pair: per joint the geodesic angle
  of the local rotations (hips: global with the facing removed), averaged over the database's joints,
  in radians. Past the take's end (plus the search window) the error is NaN.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lmm.compare import error_rotations, geodesic
from lmm.skeleton import SIMULATION_BONE_NAMES
from lmm.errors import InputError
from lmm.input_from_motion import DerivedInput, derive_input, take_root_path

SEARCH_S = 0.3          # the aligned frame is looked for this far around the tick's time


class FollowError(InputError):
    """A take that cannot be followed (its skeleton lacks the bones needed); one line naming the file."""


@dataclass
class FollowedTake:
    """A take prepared for following: the derived input and the aligned take (all arrays per take frame)."""
    name: str
    fps: float                      # the take's frame rate
    derived: DerivedInput           # one input per tick (``derived.dt``), the root paths it was judged on
    names: tuple[str, ...]          # the take's joints
    parents: np.ndarray             # (J,)
    positions: np.ndarray           # (F, J, 3) metres, aligned: the root path starts at the origin facing +Z
    rotations: np.ndarray           # (F, K, 4) the compared rotations of the database's K joints
    hips_forward_axis: tuple

    @property
    def n_frames(self) -> int:
        return len(self.positions)

    @property
    def duration_s(self) -> float:
        return (self.n_frames - 1) / self.fps

    def input_log(self):
        """The derived input as an input log (``at(t)`` gives the input of the tick after ``t``)."""
        from lmm.data.inputs import InputLog

        return InputLog.from_rows(zip(self.derived.times.tolist(), self.derived.inputs), name=f"reference {self.name}")

    def root_at(self, tick: int) -> np.ndarray:
        """The take's aligned root (simulation bone) position at the end of tick ``tick`` (1-based)."""
        p = self.derived.reference_positions
        return p[min(max(int(tick) - 1, 0), len(p) - 1)]


def follow_take(anim, manifest, joint_names, tuning=None, dt: float = 1.0 / 60.0, path: str = "",
                frames: tuple[int, int] | None = None) -> FollowedTake:
    """Prepare a loaded take (file frames ``[a, b)``, default all) for following by controllers whose
    skeleton has ``joint_names`` (the database's, a leading simulation bone is skipped). Raises
    :class:`FollowError` / :class:`InputError` with one line when the take lacks a needed bone."""
    compared = [n for n in joint_names if n not in SIMULATION_BONE_NAMES]
    missing = [n for n in compared if n not in anim.names]
    if missing:
        more = f" (and {len(missing) - 4} more)" if len(missing) > 4 else ""
        raise FollowError(f"{path}: cannot follow: the take has no joint named {', '.join(missing[:4])}{more} "
                          f"(the database's skeleton)")
    root = take_root_path(anim, manifest, path, frames)
    derived = derive_input(root, tuning, dt)
    a, b = root.frames
    g_rot, g_pos = anim.global_transforms()
    g_rot, g_pos = g_rot[a:b], g_pos[a:b] * manifest.unit_scale
    # moved so the root path starts at the origin, turned so it faces +Z (as derive_input's path)
    yaw0 = float(root.yaw[0])
    c, s = math.cos(-yaw0), math.sin(-yaw0)
    d = g_pos - np.array([root.positions[0][0], 0.0, root.positions[0][2]])
    pos = d.copy()
    pos[..., 0] = c * d[..., 0] + s * d[..., 2]
    pos[..., 2] = -s * d[..., 0] + c * d[..., 2]
    idx = [anim.names.index(n) for n in compared]
    rot, _ = error_rotations(anim.local_rotations()[a:b][:, idx], g_rot[:, idx], manifest.hips_forward_axis)
    return FollowedTake(str(path).replace("\\", "/").rsplit("/", 1)[-1], float(root.fps), derived,
                        tuple(anim.names), np.asarray(anim.parents), pos.astype(np.float32), rot,
                        tuple(manifest.hips_forward_axis))


def pose_rotations(local_rotations, global_rotations, names, hips_forward_axis) -> np.ndarray:
    """The compared rotations ``(K, 4)`` of one controller pose ``(J, 4)`` of the database skeleton."""
    first = 1 if names[0] in SIMULATION_BONE_NAMES and len(names) > 1 else 0
    rot, _ = error_rotations(np.asarray(local_rotations, np.float64)[first:],
                             np.asarray(global_rotations, np.float64)[first:], hips_forward_axis)
    return rot


class FrameTracker:
    """The aligned take frame and the pose error of one controller, tick by tick (see the module doc)."""

    def __init__(self, take: FollowedTake, search_s: float = SEARCH_S):
        self.take = take
        self.window = max(int(round(search_s * take.fps)), 0)
        self.previous = 0

    def reset(self) -> None:
        self.previous = 0

    def track(self, time_s: float, rotations: np.ndarray) -> tuple[int, float]:
        """The aligned frame and the error (radians) of a pose (compared rotations ``(K, 4)``) at ``time_s``
        from the start; past the end: the last frame and NaN."""
        take = self.take
        last = take.n_frames - 1
        at = time_s * take.fps
        if at > last + self.window:
            self.previous = last
            return last, float("nan")
        centre = int(round(at))
        lo = min(max(centre - self.window, self.previous, 0), last)
        hi = min(max(centre + self.window, lo), last)
        errors = geodesic(np.broadcast_to(rotations, take.rotations[lo:hi + 1].shape),
                          take.rotations[lo:hi + 1]).mean(axis=1)
        k = int(np.argmin(errors))
        self.previous = lo + k
        return lo + k, float(errors[k])

