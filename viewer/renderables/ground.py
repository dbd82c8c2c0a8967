"""The ground: a checkerboard with grid lines that fades into the background, and world axes."""
from __future__ import annotations

import moderngl
import numpy as np

from ..shaders import load_program
from .base import FrameState, Renderable
from .lines import Lines


class Ground(Renderable):
    """``Ground(ctx, size_m, tile_m)``: a ``size_m`` square at ``height`` (Y), tiles of ``tile_m``,
    and X/Y/Z axes (red/green/blue) of ``axis_length_m`` at the origin. With ``follow_camera`` the
    square stays centred under the camera target, so the floor never ends; the pattern is fixed in
    the world. Sizes are in scene units (scale them for a centimetre skeleton)."""

    def __init__(self, ctx: moderngl.Context, size_m: float = 40.0, tile_m: float = 1.0,
                 height: float = 0.0, axis_length_m: float | None = None, follow_camera: bool = True,
                 color_a=(0.36, 0.37, 0.40), color_b=(0.30, 0.31, 0.34), line_color=(0.22, 0.23, 0.25),
                 show_axes: bool = True):
        self.ctx = ctx
        self.size_m = float(size_m)
        self.tile_m = float(tile_m)
        self.height = float(height)
        self.follow_camera = follow_camera
        self.color_a, self.color_b, self.line_color = color_a, color_b, line_color
        self.visible = True
        self.center = np.zeros(2)
        self.program = load_program(ctx, "ground.vert", "ground.frag")
        quad = np.array([[-0.5, -0.5], [0.5, -0.5], [-0.5, 0.5], [0.5, 0.5]], dtype=np.float32)
        self._vbo = ctx.buffer(quad.tobytes())
        self._vao = ctx.vertex_array(self.program, [(self._vbo, "2f", "in_xz")])
        self.axes = Lines(ctx, width_px=3.0)
        self.show_axes = show_axes
        self.set_axis_length(tile_m if axis_length_m is None else axis_length_m)

    @property
    def receiver_height(self) -> float:
        """Shadows fall on the ground."""
        return self.height

    def set_axis_length(self, length: float) -> None:
        lift = self.height + 1e-3 * length
        o = np.array([0.0, lift, 0.0])
        pts = np.array([o, o + [length, 0, 0], o, o + [0, length, 0], o, o + [0, 0, length]])
        cols = np.array([[0.9, 0.2, 0.2]] * 2 + [[0.25, 0.85, 0.3]] * 2 + [[0.25, 0.45, 0.95]] * 2)
        self.axes.update(pts, mode="segments", colors=cols)

    def draw(self, frame: FrameState) -> None:
        if self.follow_camera:
            # snap to whole tiles so the fade ring moves but the pattern never swims
            self.center = np.round(np.asarray(frame.target)[[0, 2]] / self.tile_m) * self.tile_m
        prog = self.program
        prog["u_center"].value = tuple(float(x) for x in self.center)
        prog["u_size"].value = self.size_m
        prog["u_height"].value = self.height
        prog["u_tile"].value = self.tile_m
        prog["u_color_a"].value = tuple(self.color_a)
        prog["u_color_b"].value = tuple(self.color_b)
        prog["u_line_color"].value = tuple(self.line_color)
        prog["u_background"].value = tuple(frame.background[:3])
        frame.ctx.disable(moderngl.CULL_FACE)   # visible from below too
        self._vao.render(moderngl.TRIANGLE_STRIP)
        frame.ctx.enable(moderngl.CULL_FACE)
        if self.show_axes:
            self.axes.draw(frame)

    def release(self) -> None:
        for obj in (self._vao, self._vbo, self.program):
            obj.release()
        self.axes.release()
