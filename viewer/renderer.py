"""Offscreen rendering of a Scene seen by a camera into a (multisampled) framebuffer."""
from __future__ import annotations

import moderngl
import numpy as np

from .camera import OrbitCamera
from .renderables.base import (SOFTWARE_RENDERERS, FrameState, Resources, draw_shadows,
                               is_software_renderer)
from .scene import Scene

__all__ = ["Renderer", "SOFTWARE_RENDERERS", "is_software_renderer"]


class Renderer:
    """``Renderer(ctx, width, height, samples=None)`` owns a multisampled colour+depth framebuffer
    and a single-sample framebuffer ``fbo`` whose colour attachment is the texture ``texture``
    (RGBA8). ``samples`` is clamped to what the context supports; 0 disables MSAA; ``None`` picks
    4 on a GPU and 0 on a software rasterizer (llvmpipe), where 4x MSAA triples the frame time.

    - ``render_to(scene, camera, target=None)``: draw, resolve into ``fbo`` and, when given, copy
      the result into ``target`` (e.g. a window's ``ctx.screen``; same size). No readback.
    - ``render(scene, camera, dtype=np.uint8, out=None, flip=True)``: draw and read back an
      (H, W, 4) array; uint8 (0..255) or float32 (0..1). ``flip=True`` puts row 0 at the top (as
      images and ``OrbitCamera.project`` expect); ``flip=False`` leaves OpenGL's bottom-up rows,
      which is what a dearpygui raw texture shown with ``uv_min=(0,1), uv_max=(1,0)`` wants, with
      no extra copy. ``out`` (C-contiguous, H*W*4 elements of ``dtype``) is filled in place.

    The framebuffer bound before a render (e.g. dearpygui's) is bound again afterwards.
    """

    def __init__(self, ctx: moderngl.Context, width: int, height: int, samples: int | None = None):
        self.ctx = ctx
        if samples is None:
            samples = 0 if is_software_renderer(ctx) else 4
        self.samples = int(max(0, min(samples, ctx.max_samples)))
        if self.samples == 1:
            self.samples = 0
        self.width = self.height = 0
        self.fbo = self.texture = self._msaa = None
        self._attachments = []
        self._read_scratch = None
        Resources.of(ctx)  # compile shaders now rather than in the first frame
        self.resize(width, height)

    @property
    def size(self) -> tuple[int, int]:
        return self.width, self.height

    @property
    def aspect(self) -> float:
        return self.width / self.height

    def resize(self, width: int, height: int) -> None:
        width, height = max(int(width), 1), max(int(height), 1)
        if (width, height) == (self.width, self.height):
            return
        self._release_targets()
        self.width, self.height = width, height
        ctx = self.ctx
        self.texture = ctx.texture((width, height), 4)
        depth = ctx.depth_renderbuffer((width, height))
        self.fbo = ctx.framebuffer(color_attachments=[self.texture], depth_attachment=depth)
        self._attachments = [self.texture, depth]
        if self.samples:
            color_ms = ctx.renderbuffer((width, height), 4, samples=self.samples)
            depth_ms = ctx.depth_renderbuffer((width, height), samples=self.samples)
            self._msaa = ctx.framebuffer(color_attachments=[color_ms], depth_attachment=depth_ms)
            self._attachments += [color_ms, depth_ms]

    def _release_targets(self) -> None:
        for obj in [self._msaa, self.fbo, *self._attachments]:
            if obj is not None:
                obj.release()
        self._msaa = self.fbo = self.texture = None
        self._attachments = []

    def render_to(self, scene: Scene, camera: OrbitCamera, target: moderngl.Framebuffer | None = None) -> None:
        ctx = self.ctx
        previous = ctx.fbo
        draw_fbo = self._msaa or self.fbo
        draw_fbo.use()
        bg = scene.background
        draw_fbo.clear(bg[0], bg[1], bg[2], 1.0, depth=1.0)
        ctx.enable_only(moderngl.DEPTH_TEST | moderngl.CULL_FACE | moderngl.BLEND)
        ctx.depth_func = "<"
        ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        ctx.front_face = "ccw"
        ctx.cull_face = "back"
        frame = FrameState(ctx=ctx, fbo=draw_fbo, view=camera.view_matrix(),
                           proj=camera.projection_matrix(self.aspect), eye=camera.eye,
                           target=camera.target, width=self.width, height=self.height, background=bg,
                           light=scene.light, ground_height=scene.ground_height())
        Resources.of(ctx).begin_frame(frame, scene.light)
        order = scene.draw_order()
        opaque = [r for r in order if not r.transparent]
        for r in opaque:
            r.draw(frame)
        # shadows go on the opaque ground before anything transparent blends over it
        draw_shadows(frame, [r for r in order if r.casts_shadow], strength=scene.shadow_strength)
        for r in order[len(opaque):]:
            r.draw(frame)
        ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        if self._msaa is not None:
            ctx.copy_framebuffer(self.fbo, self._msaa)
        if target is not None:
            ctx.copy_framebuffer(target, self.fbo)
        if previous is not None and type(previous.mglo).__name__ != "InvalidObject":  # not released
            previous.use()

    def read(self, dtype=np.uint8, out: np.ndarray | None = None, flip: bool = True) -> np.ndarray:
        """Read back the last rendered image (see ``render``)."""
        dtype = np.dtype(dtype)
        if dtype not in (np.dtype(np.uint8), np.dtype(np.float32)):
            raise ValueError("dtype must be uint8 or float32")
        shape = (self.height, self.width, 4)
        if out is not None:
            if out.dtype != dtype or out.size != self.width * self.height * 4 or not out.flags.c_contiguous:
                raise ValueError(f"out must be a C-contiguous {dtype} array of {self.height}x{self.width}x4 values")
        gl_dtype = "f1" if dtype == np.uint8 else "f4"
        if not flip:
            target = out if out is not None else np.empty(shape, dtype)
            self.fbo.read_into(target, components=4, dtype=gl_dtype)
            return target.reshape(shape)
        if self._read_scratch is None or self._read_scratch.shape != shape or self._read_scratch.dtype != dtype:
            self._read_scratch = np.empty(shape, dtype)
        self.fbo.read_into(self._read_scratch, components=4, dtype=gl_dtype)
        if out is None:
            return self._read_scratch[::-1].copy()
        view = out.reshape(shape)
        view[...] = self._read_scratch[::-1]
        return view

    def render(self, scene: Scene, camera: OrbitCamera, dtype=np.uint8, out: np.ndarray | None = None,
               flip: bool = True) -> np.ndarray:
        self.render_to(scene, camera)
        return self.read(dtype=dtype, out=out, flip=flip)

    def project(self, camera: OrbitCamera, points) -> np.ndarray:
        """Pixel coordinates of world points in this renderer's (flipped) images."""
        return camera.project(points, self.width, self.height)

    def release(self) -> None:
        self._release_targets()
