"""Arrows (facing directions, velocities): a cylinder shaft and a cone head per arrow."""
from __future__ import annotations

import moderngl
import numpy as np

from .base import (MESH_INSTANCE_FLOATS, FrameState, InstanceBuffer, Renderable, Resources,
                   as_rgba, draw_mesh_instances, same_fixed_inputs)


class Arrows(Renderable):
    """``Arrows(ctx, color, shaft_radius, head_radius, head_length)``; ``update(origins (N,3),
    directions (N,3), colors=None)``: each arrow goes from origin to origin + direction. The head
    is at most half the arrow's length, so short arrows stay arrows."""

    def __init__(self, ctx: moderngl.Context, color=(0.95, 0.95, 0.3), shaft_radius: float = 0.01,
                 head_radius: float = 0.03, head_length: float = 0.08):
        self.ctx = ctx
        self.color = color
        self.shaft_radius = float(shaft_radius)
        self.head_radius = float(head_radius)
        self.head_length = float(head_length)
        self.visible = True
        res = Resources.of(ctx)
        self._shafts = InstanceBuffer(ctx, MESH_INSTANCE_FLOATS)
        self._heads = InstanceBuffer(ctx, MESH_INSTANCE_FLOATS)
        self._shaft_vao = res.mesh_vao("cylinder", self._shafts.buffer)
        self._head_vao = res.mesh_vao("cone", self._heads.buffer)
        self._fixed = None      # the inputs of the radius and colour columns the staging arrays hold

    def prepare(self, origins, directions) -> tuple:
        """``(origins, necks, tips)`` float32 (N, 3) of the arrows: what ``update`` computes of them, without
        GL or a change to this object (safe on another thread; pass it to ``update`` as ``prepared``)."""
        o = np.asarray(origins, dtype=np.float32).reshape(-1, 3)
        d = np.broadcast_to(np.asarray(directions, dtype=np.float32).reshape(-1, 3), o.shape)
        length = np.sqrt(np.add.reduce(d * d, axis=1))   # np.linalg.norm's sum, without its overhead
        head = np.minimum(self.head_length, 0.5 * length)
        unit = d / np.maximum(length, 1e-12)[:, None]
        return o, o + unit * (length - head)[:, None], o + d

    def update(self, origins, directions, colors=None, prepared: tuple | None = None) -> None:
        """``prepared``: ``prepare(origins, directions)`` made with this head length (then the two arrays
        are not read again)."""
        o, neck, tip = self.prepare(origins, directions) if prepared is None else prepared
        shafts = self._shafts.staging(len(o))
        heads = self._heads.staging(len(o))
        shafts[:, 0:3] = o
        shafts[:, 3:6] = neck
        heads[:, 0:3] = neck
        heads[:, 3:6] = tip
        # unchanged colours (the same frozen array, the same default) and radii are still in the
        # staging arrays: only the ends are written
        fixed = ((shafts.base, heads.base), (colors, self.color, self.shaft_radius, self.head_radius, len(o)))
        if not same_fixed_inputs(self._fixed, fixed):
            rgba = as_rgba(self.color if colors is None else colors)
            shafts[:, 6] = self.shaft_radius
            shafts[:, 7:11] = rgba
            heads[:, 6] = self.head_radius
            heads[:, 7:11] = rgba
            self._fixed = fixed
        self._shafts.upload(shafts)
        self._heads.upload(heads)

    def draw(self, frame: FrameState) -> None:
        draw_mesh_instances(frame, self._shaft_vao, self._shafts.count)
        draw_mesh_instances(frame, self._head_vao, self._heads.count, cone=True)

    def release(self) -> None:
        for obj in (self._shaft_vao, self._head_vao, self._shafts, self._heads):
            obj.release()
