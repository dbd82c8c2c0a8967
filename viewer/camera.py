"""Orbit camera and projection math (pure numpy, no GL).

Scene coordinates are Y-up and right-handed. Matrices are row-major float32 and act on column
vectors (``clip = proj @ view @ [x, y, z, 1]``); upload them to GLSL transposed.

Camera controls are plain functions of input deltas (pixels, wheel steps), so the studio and the
glfw player drive one camera type the same way.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np



def look_at(eye, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """World -> view matrix of a camera at ``eye`` looking at ``target`` (view looks down -Z)."""
    return np.array([*_look_at_rows(eye, target, up), (0.0, 0.0, 0.0, 1.0)], dtype=np.float32)


def _look_at_rows(eye, target, up=(0.0, 1.0, 0.0)) -> tuple:
    """The first three rows of :func:`look_at`, as float64 tuples (the last row is 0, 0, 0, 1)."""
    # plain float arithmetic: numpy's per-call overhead on 3-vectors is most of the cost otherwise
    ex, ey, ez = (float(v) for v in eye)
    tx, ty, tz = (float(v) for v in target)
    ux, uy, uz = (float(v) for v in up)
    fx, fy, fz = tx - ex, ty - ey, tz - ez
    n = max(math.sqrt(fx * fx + fy * fy + fz * fz), 1e-12)
    fx, fy, fz = fx / n, fy / n, fz / n
    rx, ry, rz = fy * uz - fz * uy, fz * ux - fx * uz, fx * uy - fy * ux
    n = math.sqrt(rx * rx + ry * ry + rz * rz)
    if n < 1e-9:  # looking straight along `up`: any right vector will do (forward x +Z)
        rx, ry, rz = fy, -fx, 0.0
        n = math.sqrt(rx * rx + ry * ry)
    rx, ry, rz = rx / n, ry / n, rz / n
    vx, vy, vz = ry * fz - rz * fy, rz * fx - rx * fz, rx * fy - ry * fx
    return ((rx, ry, rz, -(rx * ex + ry * ey + rz * ez)),
            (vx, vy, vz, -(vx * ex + vy * ey + vz * ez)),
            (-fx, -fy, -fz, fx * ex + fy * ey + fz * ez))


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL perspective projection (NDC depth in [-1, 1])."""
    a, f, c, d = _perspective_terms(fov_y_deg, aspect, near, far)
    return np.array([[a, 0.0, 0.0, 0.0], [0.0, f, 0.0, 0.0], [0.0, 0.0, c, d], [0.0, 0.0, -1.0, 0.0]],
                    dtype=np.float32)


def _perspective_terms(fov_y_deg: float, aspect: float, near: float, far: float) -> tuple:
    """The four non-constant entries of :func:`perspective` (x scale, y scale, depth scale and offset),
    float64: plain floats, the same IEEE doubles as numpy's scalar maths, a tenth of the calls."""
    f = 1.0 / math.tan(math.radians(fov_y_deg) / 2.0)
    return f / aspect, f, (far + near) / (near - far), 2.0 * far * near / (near - far)


def project_points(points, view_proj: np.ndarray, width: int, height: int):
    """Project world points to pixel coordinates.

    Returns ``(pixels (N,2), ndc_depth (N,), in_front (N,) bool)``; pixels are (x right, y down)
    from the top-left corner of the image as returned by ``Renderer.render`` (row 0 = top), so
    ``image[int(y), int(x)]`` is the pixel the point lands on.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    homogeneous = np.empty((len(p), 4))
    homogeneous[:, :3] = p
    homogeneous[:, 3] = 1.0
    clip = homogeneous @ np.asarray(view_proj, dtype=np.float64).T
    w = clip[:, 3]
    in_front = w > 1e-9
    safe_w = np.where(in_front, w, 1.0)
    ndc = clip[:, :3] / safe_w[:, None]
    pixels = np.empty((len(p), 2))
    pixels[:, 0] = (ndc[:, 0] + 1.0) * 0.5 * width
    pixels[:, 1] = (1.0 - ndc[:, 1]) * 0.5 * height
    return pixels, ndc[:, 2], in_front


def project_points_floats(points, view_proj: np.ndarray, width: int, height: int) -> list:
    """:func:`project_points` for a few points in plain floats (labels: three or four a frame, where
    numpy's per-call cost is most of the work): ``[(x, y, in_front), ...]`` with the same pixel
    convention, equal to its pixels to float64 rounding."""
    rows = view_proj if isinstance(view_proj, tuple) else np.asarray(view_proj, np.float64).tolist()
    (a0, a1, a2, a3), (b0, b1, b2, b3), _, (d0, d1, d2, d3) = rows
    half_w, half_h = 0.5 * width, 0.5 * height
    out = []
    for p in points:
        x, y, z = float(p[0]), float(p[1]), float(p[2])
        w = d0 * x + d1 * y + d2 * z + d3
        front = w > 1e-9
        if not front:
            w = 1.0
        out.append(((( a0 * x + a1 * y + a2 * z + a3) / w + 1.0) * half_w,
                    (1.0 - (b0 * x + b1 * y + b2 * z + b3) / w) * half_h, front))
    return out


@dataclass
class OrbitCamera:
    """A camera orbiting ``target`` at ``distance``.

    ``yaw_deg`` turns about +Y (0 looks from +Z towards -Z); ``pitch_deg`` is the elevation of the
    eye above the target's horizontal plane (positive looks down). Near/far planes follow the
    distance so any unit (m, cm, inches) works once ``fit`` has sized the camera.
    """

    target: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.9, 0.0]))
    distance: float = 4.0
    yaw_deg: float = 30.0
    pitch_deg: float = 15.0
    fov_y_deg: float = 45.0
    min_distance: float = 1e-3
    max_distance: float = 1e6
    min_pitch_deg: float = -85.0
    max_pitch_deg: float = 89.0
    near_ratio: float = 0.01   # near plane = near_ratio * distance
    far_ratio: float = 200.0   # far plane = far_ratio * distance

    def __post_init__(self):
        self.target = np.asarray(self.target, dtype=np.float64).copy()
        self._view_key, self._view = None, None
        self._vp_key, self._vp = None, None

    # ---- geometry ---------------------------------------------------------------------------
    @property
    def eye(self) -> np.ndarray:
        return np.array(self._eye())

    def _eye(self) -> tuple:
        yaw, pitch = math.radians(self.yaw_deg), math.radians(self.pitch_deg)
        t, d = self.target, self.distance
        return (float(t[0]) + d * (math.cos(pitch) * math.sin(yaw)), float(t[1]) + d * math.sin(pitch),
                float(t[2]) + d * (math.cos(pitch) * math.cos(yaw)))

    @property
    def near(self) -> float:
        return self.distance * self.near_ratio

    @property
    def far(self) -> float:
        return self.distance * self.far_ratio

    def view_matrix(self) -> np.ndarray:
        # computed once per camera placement (labels and the render both ask each frame); a copy, so
        # callers may keep or change what they get
        t = self.target
        key = (float(t[0]), float(t[1]), float(t[2]), self.distance, self.yaw_deg, self.pitch_deg)
        if self._view_key != key:
            self._view = look_at(self._eye(), key[:3])
            self._view_key = key
        return self._view.copy()

    def projection_matrix(self, aspect: float) -> np.ndarray:
        return perspective(self.fov_y_deg, aspect, self.near, self.far)

    def view_projection(self, aspect: float) -> np.ndarray:
        """projection @ view (float32), as :meth:`view_projection_rows` works it out in float64."""
        return np.array(self.view_projection_rows(aspect), dtype=np.float32)

    def view_projection_rows(self, aspect: float) -> tuple:
        """projection @ view as four float64 row tuples, kept per camera placement and aspect: the studio's
        labels project through it every frame (plain floats: the numpy form cost 20-100 us a frame).
        The product of the two float64 matrices before their rounding to float32, so within a float32
        rounding of ``projection_matrix(aspect) @ view_matrix()``."""
        t = self.target
        key = (float(t[0]), float(t[1]), float(t[2]), self.distance, self.yaw_deg, self.pitch_deg,
               self.fov_y_deg, self.near_ratio, self.far_ratio, float(aspect))
        if self._vp_key != key:
            r0, r1, r2 = _look_at_rows(self._eye(), key[:3])
            a, f, c, d = _perspective_terms(self.fov_y_deg, aspect, self.near, self.far)
            self._vp = (tuple(a * v for v in r0), tuple(f * v for v in r1),
                        (c * r2[0], c * r2[1], c * r2[2], c * r2[3] + d), tuple(-v for v in r2))
            self._vp_key = key
        return self._vp

    def basis(self):
        """(right, up, forward) unit vectors of the camera in world space."""
        v = self.view_matrix().astype(np.float64)
        return v[0, :3], v[1, :3], -v[2, :3]

    def project(self, points, width: int, height: int) -> np.ndarray:
        """Pixel coordinates (N,2), x right / y down from the image's top-left corner."""
        pixels, _, _ = project_points(points, self.view_projection(width / height), width, height)
        return pixels

    # ---- controls (plain functions of input deltas) ------------------------------------------
    def orbit(self, dx_px: float, dy_px: float, deg_per_px: float = 0.4) -> None:
        """Drag right turns the scene right; drag down looks from higher up."""
        self.yaw_deg = (self.yaw_deg - dx_px * deg_per_px) % 360.0
        self.pitch_deg = float(np.clip(self.pitch_deg + dy_px * deg_per_px,
                                       self.min_pitch_deg, self.max_pitch_deg))

    def zoom(self, steps: float, factor: float = 1.15) -> None:
        """Positive steps (wheel up) move closer; each step divides the distance by ``factor``."""
        self.distance = float(np.clip(self.distance * factor ** (-steps),
                                      self.min_distance, self.max_distance))

    def pan(self, dx_px: float, dy_px: float, viewport_height_px: float) -> None:
        """Move the target in the view plane so that points at the target's depth follow the cursor."""
        right, up, _ = self.basis()
        world_per_px = 2.0 * self.distance * np.tan(np.radians(self.fov_y_deg) / 2.0) / viewport_height_px
        self.target = self.target + (-dx_px * right + dy_px * up) * world_per_px

    def follow(self, position, blend: float = 1.0, keep_height: bool = True) -> None:
        """Track a character root: move the target towards ``position`` (horizontally by default,
        so the root's bobbing does not shake the view). ``blend`` in (0, 1] smooths the motion."""
        # plain floats (the studio follows every frame): the same operations per component as numpy's
        b = float(blend)
        t0, t1, t2 = (float(v) for v in self.target)
        g0, g1, g2 = (float(v) for v in position)
        if keep_height:
            g1 = t1
        self.target = np.array([t0 + b * (g0 - t0), t1 + b * (g1 - t1), t2 + b * (g2 - t2)])

    def fit(self, points, aspect: float = 16 / 9, margin: float = 1.15) -> None:
        """Aim at the bounding box centre of ``points`` and set the distance so their bounding
        sphere (times ``margin``) fits the narrower field of view. Keeps yaw and pitch."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        p = p[np.isfinite(p).all(axis=1)]
        if len(p) == 0:
            return
        lo, hi = p.min(axis=0), p.max(axis=0)
        center = (lo + hi) / 2.0
        radius = max(float(np.linalg.norm(p - center, axis=1).max()), 1e-6)
        half_fov_y = np.radians(self.fov_y_deg) / 2.0
        half_fov_x = np.arctan(np.tan(half_fov_y) * aspect)
        self.target = center
        self.distance = float(np.clip(radius * margin / np.sin(min(half_fov_y, half_fov_x)),
                                      self.min_distance, self.max_distance))


def apply_drag(camera: OrbitCamera, button: str, dx_px: float, dy_px: float,
               viewport_height_px: float) -> None:
    """Mouse drag: left orbits, right or middle pans."""
    if button == "left":
        camera.orbit(dx_px, dy_px)
    elif button in ("right", "middle"):
        camera.pan(dx_px, dy_px, viewport_height_px)


def apply_scroll(camera: OrbitCamera, wheel_steps: float) -> None:
    """Mouse wheel: zoom towards the target."""
    camera.zoom(wheel_steps)
