"""Playing an animation given as arrays: the scene, camera framing and playback clock shared by
the glfw player window and headless screenshots. No window code here.

Works in any unit: the character's height sets the joint radii, ground tiles and camera distance,
so a take in centimetres, metres or inches is framed the same way.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import moderngl
import numpy as np

from .camera import OrbitCamera
from .renderables import Ground, Lines, Skeleton, radii_for_height
from .scene import Scene

NOMINAL_HEIGHT_M = 1.7   # a character this tall in scene units counts as one "metre" of scale


@dataclass
class Proportions:
    """Size of a character measured from its animation, in file units."""

    height: float        # typical head-to-toe extent
    floor: float         # height of the ground under the feet
    unit_scale: float    # scene units per metre, guessed from the height (1 for m, ~100 for cm)
    root_height: float   # typical height of the root (hips) above the floor

    def lift(self, root_y: float) -> float:
        """How far the character stands above the floor (climbing, jumping), ignoring the small
        ups and downs of walking so a following camera does not bob."""
        return max(0.0, root_y - self.floor - self.root_height - 0.15 * self.height)

    def view_center_y(self, root_y: float) -> float:
        """Height to aim at: the middle of a standing body where the character is."""
        return self.floor + self.lift(root_y) + 0.5 * self.height


def measure(positions: np.ndarray, max_samples: int = 256) -> Proportions:
    """Estimate height and floor from global positions (F, J, 3), Y up, on up to ``max_samples``
    evenly spaced frames (robust to a few crouched or jumping frames)."""
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim == 2:
        p = p[None]
    idx = np.unique(np.linspace(0, len(p) - 1, min(len(p), max_samples)).astype(int))
    s = p[idx]
    s = np.where(np.isfinite(s), s, np.nan)
    extent_y = np.nanmax(s[..., 1], axis=1) - np.nanmin(s[..., 1], axis=1)
    height = float(np.nanpercentile(extent_y, 90)) if np.isfinite(extent_y).any() else 0.0
    if not height > 0:
        span = np.nanmax(s.reshape(-1, 3), axis=0) - np.nanmin(s.reshape(-1, 3), axis=0)
        height = float(np.nanmax(span)) if np.isfinite(span).any() else 0.0
    if not height > 0:
        height = 1.0
    floor = float(np.nanpercentile(np.nanmin(s[..., 1], axis=1), 5))
    if not np.isfinite(floor) or abs(floor) < 0.05 * height:
        floor = 0.0   # the file's own origin is the floor
    root_height = float(np.nanmedian(s[:, 0, 1])) - floor
    if not np.isfinite(root_height):
        root_height = 0.5 * height
    return Proportions(height=height, floor=floor, unit_scale=height / NOMINAL_HEIGHT_M,
                       root_height=root_height)


def frame_character(camera: OrbitCamera, pose, props: Proportions, aspect: float,
                    margin: float = 1.1) -> None:
    """Aim the camera at the character whose global joint positions are ``pose`` (J, 3; joint 0
    is the root) and set the distance so a standing body of its height fits there, and the
    current pose too (a crouch does not zoom in, a jump or a climb is not cut off)."""
    pose = np.asarray(pose, dtype=np.float64).reshape(-1, 3)
    h = props.height
    root = pose[0]
    base = props.floor + props.lift(root[1])
    box = np.array([[root[0] - 0.3 * h, base, root[2] - 0.3 * h],
                    [root[0] + 0.3 * h, base + h, root[2] + 0.3 * h]])
    camera.fit(np.r_[box, pose[np.isfinite(pose).all(axis=1)]], aspect=aspect, margin=margin)


@dataclass
class Playback:
    """A looping clock over ``n_frames`` frames of ``frame_time`` seconds."""

    n_frames: int
    frame_time: float
    speed: float = 1.0
    paused: bool = False
    time: float = 0.0
    speeds: tuple = field(default=(0.125, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0))

    @property
    def duration(self) -> float:
        return self.n_frames * self.frame_time

    @property
    def frame(self) -> int:
        return int(np.floor(self.time / self.frame_time + 1e-6)) % max(self.n_frames, 1)

    def advance(self, dt: float) -> int:
        if not self.paused and self.n_frames > 1:
            self.time = (self.time + dt * self.speed) % self.duration
        return self.frame

    def step(self, frames: int) -> int:
        """Pause and move by whole frames (arrow keys)."""
        self.paused = True
        self.seek((self.frame + frames) % self.n_frames)
        return self.frame

    def seek(self, frame: int) -> None:
        self.time = (int(frame) % max(self.n_frames, 1)) * self.frame_time

    def faster(self) -> None:
        self.speed = next((s for s in self.speeds if s > self.speed + 1e-9), self.speeds[-1])

    def slower(self) -> None:
        self.speed = next((s for s in reversed(self.speeds) if s < self.speed - 1e-9), self.speeds[0])


class AnimationView:
    """A Scene showing one animated skeleton, its root path on the ground (``path_window_frames``
    before and after the current frame, fading from past to future) and a camera that can follow
    it. ``set_frame(i)`` poses the skeleton and moves a following camera. ``names``, ``body_radii``,
    ``style`` and ``shadow`` go to the :class:`Skeleton` (``view.skeleton.style = "sticks"`` switches later)."""

    def __init__(self, ctx: moderngl.Context, parents, positions, aspect: float = 16 / 9,
                 color=(0.95, 0.55, 0.15), follow: bool = True, path_window_frames: int = 120,
                 names=None, style: str = "capsules", shadow: bool = True, body_radii=None):
        self.positions = np.asarray(positions, dtype=np.float32)
        if self.positions.ndim != 3 or self.positions.shape[-1] != 3 or len(self.positions) == 0:
            raise ValueError(f"positions must be (frames, joints, 3) with at least one frame, "
                             f"got shape {self.positions.shape}")
        self.parents = np.asarray(parents, dtype=np.int64)
        self.props = measure(self.positions)
        s = self.props.unit_scale
        self.scene = Scene()
        self.ground = self.scene.add(Ground(ctx, size_m=60.0 * s, tile_m=1.0 * s, height=self.props.floor,
                                            axis_length_m=0.5 * s))
        self.root_path = self.positions[:, 0].copy()
        self.root_path[:, 1] = self.props.floor
        self.path_window = path_window_frames
        self.path = self.scene.add(Lines(ctx, color=(0.35, 0.75, 0.95), width_px=2.0))
        self.skeleton = self.scene.add(Skeleton(ctx, self.parents, color=color, names=names, style=style,
                                                shadow=shadow, body_radii=body_radii,
                                                **radii_for_height(self.props.height)))
        self.camera = OrbitCamera(yaw_deg=35.0, pitch_deg=12.0)
        self.aspect = aspect
        self.follow = follow
        self.frame = 0
        self.reset_camera(0)

    @property
    def n_frames(self) -> int:
        return len(self.positions)

    def root(self, frame: int) -> np.ndarray:
        return self.positions[frame, 0].astype(np.float64)

    def reset_camera(self, frame: int | None = None) -> None:
        frame = self.frame if frame is None else int(frame) % self.n_frames
        frame_character(self.camera, self.positions[frame], self.props, self.aspect)

    def set_frame(self, frame: int) -> None:
        self.frame = int(frame) % self.n_frames
        self.skeleton.update(self.positions[self.frame])
        lo, hi = max(self.frame - self.path_window, 0), min(self.frame + self.path_window + 1, self.n_frames)
        if hi - lo >= 2:
            t = (np.arange(lo, hi) - self.frame) / max(self.path_window, 1)   # -1 past .. +1 future
            colors = np.empty((hi - lo, 4), dtype=np.float32)
            colors[:, :3] = np.where(t[:, None] < 0, (0.55, 0.6, 0.7), (0.35, 0.8, 1.0))
            colors[:, 3] = 1.0 - 0.7 * np.abs(t)
            self.path.update(self.root_path[lo:hi], colors=colors)
        self.path.visible = hi - lo >= 2
        if self.follow:
            root = self.root(self.frame)
            self.camera.follow([root[0], self.props.view_center_y(root[1]), root[2]], keep_height=False)
