"""Thick lines and polylines (trajectories, velocities), a constant width in pixels."""
from __future__ import annotations

import moderngl
import numpy as np

from .base import (LINE_INSTANCE_FLOATS, FrameState, InstanceBuffer, Renderable, Resources, as_rgba,
                   same_fixed_inputs, set_depth_write)


class Lines(Renderable):
    """``Lines(ctx, color, width_px)``; ``update(points (N,3), mode='strip'|'segments',
    colors=None)``. ``strip`` joins consecutive points; ``segments`` draws pairs (0,1), (2,3)...
    ``colors`` is one colour or one per point (N, 3|4), interpolated along each segment."""

    def __init__(self, ctx: moderngl.Context, color=(1.0, 1.0, 1.0), width_px: float = 3.0,
                 depth_pull: float = 2e-3):
        self.ctx = ctx
        self.color = color
        self.width_px = float(width_px)
        self.depth_pull = float(depth_pull)  # fraction of view distance: wins ties with the ground
        self.visible = True
        self._buf = InstanceBuffer(ctx, LINE_INSTANCE_FLOATS)
        self._vao = Resources.of(ctx).line_vao(self._buf.buffer)
        self._fixed = None      # the inputs of the colour columns the staging array holds
        self._transparent = False

    @property
    def transparent(self) -> bool:
        return self._transparent

    def update(self, points, mode: str = "strip", colors=None) -> None:
        p = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        # each segment's first and second point, as slices (views: no index arrays, no gathers)
        if mode == "strip":
            i0, i1 = slice(0, max(len(p) - 1, 0)), slice(1, None)
        elif mode == "segments":
            if len(p) % 2:
                raise ValueError("mode='segments' needs an even number of points")
            i0, i1 = slice(0, None, 2), slice(1, None, 2)
        else:
            raise ValueError(f"unknown mode {mode!r}: use 'strip' or 'segments'")
        data = self._buf.staging(len(p[i0]))
        data[:, 0:3] = p[i0]
        data[:, 3:6] = p[i1]
        # unchanged colours (the same frozen array, the same default) for the same segments are still
        # in the staging array: only the ends are written
        fixed = ((data.base,), (colors, self.color, mode, len(p)))
        if not same_fixed_inputs(self._fixed, fixed):
            self._fixed = None
            rgba = as_rgba(self.color if colors is None else colors)
            per_point = rgba.ndim == 2
            if per_point and len(rgba) != len(p):
                raise ValueError(f"{len(rgba)} colours for {len(p)} points")
            data[:, 6:10] = rgba[i0] if per_point else rgba
            data[:, 10:14] = rgba[i1] if per_point else rgba
            self._transparent = bool(len(data) and ((data[:, 9] < 1.0).any() or (data[:, 13] < 1.0).any()))
            self._fixed = fixed
        self._buf.upload(data)

    def draw(self, frame: FrameState) -> None:
        if self._buf.count == 0:
            return
        prog = self._vao.program
        prog["u_width_px"].value = self.width_px
        prog["u_depth_pull"].value = self.depth_pull
        frame.ctx.disable(moderngl.CULL_FACE)
        if self._transparent:
            set_depth_write(frame.fbo, False)
        self._vao.render(moderngl.TRIANGLE_STRIP, instances=self._buf.count)
        if self._transparent:
            set_depth_write(frame.fbo, True)
        frame.ctx.enable(moderngl.CULL_FACE)

    def release(self) -> None:
        self._vao.release()
        self._buf.release()
