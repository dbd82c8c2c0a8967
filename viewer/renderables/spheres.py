"""Spheres (feature markers, foot contacts, points) drawn instanced."""
from __future__ import annotations

import moderngl
import numpy as np

from .base import (MESH_INSTANCE_FLOATS, FrameState, InstanceBuffer, Renderable, Resources,
                   as_rgba, draw_mesh_instances, same_fixed_inputs, set_depth_write)


class Spheres(Renderable):
    """``Spheres(ctx, color, radius)``; ``update(centers (N,3), radii (N,) or scalar, colors
    (N,3|4) or one colour)``. Any colour with alpha < 1 makes the set transparent."""

    def __init__(self, ctx: moderngl.Context, color=(0.9, 0.9, 0.9), radius: float = 0.03):
        self.ctx = ctx
        self.color = color
        self.radius = float(radius)
        self.visible = True
        self._buf = InstanceBuffer(ctx, MESH_INSTANCE_FLOATS)
        self._vao = Resources.of(ctx).mesh_vao("sphere", self._buf.buffer)
        self._transparent = False
        self._fixed = None      # the inputs of the radius and colour columns the staging array holds

    @property
    def transparent(self) -> bool:
        return self._transparent

    def update(self, centers, radii=None, colors=None) -> None:
        c = np.asarray(centers, dtype=np.float32).reshape(-1, 3)
        data = self._buf.staging(len(c))
        data[:, 0:3] = c
        data[:, 3:6] = c
        # radii and colours that did not change (the same frozen arrays, the same defaults) are still
        # in the staging array: only the centres are written
        fixed = ((data.base,), (radii, colors, self.radius, self.color, len(c)))
        if not same_fixed_inputs(self._fixed, fixed):
            data[:, 6] = self.radius if radii is None else np.broadcast_to(np.asarray(radii, np.float32), len(c))
            rgba = as_rgba(self.color if colors is None else colors)
            data[:, 7:11] = rgba
            self._transparent = bool(len(c) and (data[:, 10] < 1.0).any())
            self._fixed = fixed
        self._buf.upload(data)

    def draw(self, frame: FrameState) -> None:
        if self._transparent:
            set_depth_write(frame.fbo, False)
            draw_mesh_instances(frame, self._vao, self._buf.count)
            set_depth_write(frame.fbo, True)
        else:
            draw_mesh_instances(frame, self._vao, self._buf.count)

    def release(self) -> None:
        self._vao.release()
        self._buf.release()


Points = Spheres
