"""A skeleton drawn as lit bones (cylinders from parent to child) and joint spheres."""
from __future__ import annotations

import moderngl
import numpy as np

from .base import (MESH_INSTANCE_FLOATS, FrameState, InstanceBuffer, Renderable, Resources,
                   as_rgba, draw_mesh_instances, draw_transparent)


def radii_for_height(height: float) -> dict:
    """Joint and bone radii proportional to a character's height, in the same units, so a skeleton
    in metres, centimetres or inches looks the same: ``Skeleton(ctx, parents, **radii_for_height(h))``."""
    return {"joint_radius": 0.016 * height, "bone_radius": 0.011 * height}


class Skeleton(Renderable):
    """``Skeleton(ctx, parents, color, alpha, joint_radius, bone_radius)``; ``update(positions)``
    with global joint positions (J, 3). ``alpha < 1`` draws a ghost (single-layer blend).

    ``color``, ``alpha`` and the radii can be changed at any time; they apply on the next draw.
    """

    def __init__(self, ctx: moderngl.Context, parents, color=(0.95, 0.55, 0.15), alpha: float = 1.0,
                 joint_radius: float = 0.028, bone_radius: float = 0.019):
        self.ctx = ctx
        self.parents = np.asarray(parents, dtype=np.int64).ravel()
        self.color = tuple(float(c) for c in color[:3])
        self.alpha = float(alpha)
        self.joint_radius = float(joint_radius)
        self.bone_radius = float(bone_radius)
        self.visible = True
        self._children = np.nonzero(self.parents >= 0)[0]
        self._bone_parents = self.parents[self._children]
        res = Resources.of(ctx)
        n = len(self.parents)
        self._joints = InstanceBuffer(ctx, MESH_INSTANCE_FLOATS, max(n, 1))
        self._bones = InstanceBuffer(ctx, MESH_INSTANCE_FLOATS, max(len(self._children), 1))
        self._joint_vao = res.mesh_vao("sphere", self._joints.buffer)
        self._bone_vao = res.mesh_vao("cylinder", self._bones.buffer)
        self._positions = None
        self._uploaded_style = None

    @property
    def n_joints(self) -> int:
        return len(self.parents)

    @property
    def transparent(self) -> bool:
        return self.alpha < 1.0

    def _style(self):
        return (self.color, self.alpha, self.joint_radius, self.bone_radius)

    def update(self, global_positions) -> None:
        """Set the pose: global joint positions (J, 3) in scene units."""
        p = np.asarray(global_positions, dtype=np.float32).reshape(-1, 3)
        if len(p) != self.n_joints:
            raise ValueError(f"Skeleton has {self.n_joints} joints, got positions for {len(p)}")
        self._positions = p
        self._upload()

    def _upload(self) -> None:
        p = self._positions
        rgba = as_rgba(self.color, alpha=self.alpha)
        j = self._joints.staging(len(p))
        j[:, 0:3] = p
        j[:, 3:6] = p
        j[:, 6] = self.joint_radius
        j[:, 7:11] = rgba
        self._joints.upload(j)
        b = self._bones.staging(len(self._children))
        b[:, 0:3] = p[self._bone_parents]
        b[:, 3:6] = p[self._children]
        b[:, 6] = self.bone_radius
        b[:, 7:10] = rgba[:3] * 0.85   # bones a little darker than joints, same hue
        b[:, 10] = rgba[3]
        self._bones.upload(b)
        self._uploaded_style = self._style()

    def draw(self, frame: FrameState) -> None:
        if self._positions is None:
            return
        if self._uploaded_style != self._style():
            self._upload()
        draws = [lambda: draw_mesh_instances(frame, self._bone_vao, self._bones.count),
                 lambda: draw_mesh_instances(frame, self._joint_vao, self._joints.count)]
        if self.transparent:
            draw_transparent(frame, draws)
        else:
            for d in draws:
                d()

    def release(self) -> None:
        for obj in (self._joint_vao, self._bone_vao, self._joints, self._bones):
            obj.release()
