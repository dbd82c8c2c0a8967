"""How the 3D view's pixels reach dearpygui: drawn by :mod:`viewer` into its own framebuffer in
dearpygui's GL context and copied on the GPU into the OpenGL texture of a dearpygui static texture
(:mod:`app.gl_texture`); where that texture cannot be found (or with ``--readback-3d``) the pixels are
read back into a raw texture instead, which dearpygui uploads again every frame."""
from __future__ import annotations

import time

import numpy as np

from ..gl_texture import SharedTexture, marker_image, texture_names

BYTE_TO_UNIT = np.float32(1.0 / 255.0)          # an 8-bit colour channel to the raw texture's 0..1


class ViewTexture:
    """The dearpygui texture the 3D view is shown in, remade with every new size, and the copy of each
    rendered picture into it."""

    #: frames to wait for dearpygui to make a static texture before reading back instead
    SHARED_TEXTURE_TRIES = 3

    def __init__(self, dpg, readback: bool = False):
        self.dpg = dpg
        self.gl = self.renderer = None
        self.tag = None                    # the dearpygui texture's tag (a new one with every size)
        self.tex_array = None              # the raw texture's pixels (readback path only)
        self._read_bytes = None
        self._shared = None                # the static texture's SharedTexture (direct path)
        # why the view is read back instead of drawn into dearpygui's texture (None: it is not)
        self.readback_why = "--readback-3d" if readback else None
        self._names = None
        self._counter = 0
        self._screen_fbo = None
        self.unread = False                # a picture was rendered that finish() has not copied yet
        self.remake_due = False            # the shared texture was given up: the owner remakes it (raw)
        self.readback_ms = 0.0

    def attach(self, gl, renderer) -> None:
        """The GL context and renderer (after dearpygui's first frame); the texture names are listed
        now, while no texture of the view exists yet."""
        self.gl, self.renderer = gl, renderer
        if self.readback_why is None:
            self._names, why = texture_names()
            if self._names is None:
                self.readback_why = why

    def path(self) -> str:
        """How the 3D view reaches the screen: "direct" (copied on the GPU into dearpygui's texture),
        "readback" (read back and uploaded each frame) or "pending" (looking for the texture)."""
        if self._shared is None:
            return "readback"
        return "direct" if self._shared.fbo is not None else "pending"

    def remake(self, rw: int, rh: int, background) -> tuple:
        """A new texture of ``rw`` x ``rh`` texels; returns the old one's (tag, SharedTexture or None) for
        :meth:`drop` once the image shows the new one."""
        dpg = self.dpg
        old = (self.tag, self._shared)
        self._counter += 1
        self.tag = f"vp_texture_{self._counter}"
        self._shared = None
        if self.readback_why is None:
            # a static texture dearpygui makes during this frame and never writes again: finish fills
            # it with this frame's picture first, the view is copied into it from the next frame on
            marker = marker_image(rw, rh, background, self._counter)
            dpg.add_static_texture(rw, rh, marker.ravel(), tag=self.tag, parent="texture_registry")
            self.tex_array = self._read_bytes = None
            try:
                self._shared = SharedTexture(self.gl, self._names, rw, rh, marker)
            except Exception as e:      # a GL library that does not answer: read back instead
                self.give_up_shared(f"texture names not readable: {e}")
        else:
            self.tex_array = np.zeros((rh, rw, 4), dtype=np.float32)
            self.tex_array[..., 3] = 1.0
            self._read_bytes = np.zeros((rh, rw, 4), dtype=np.uint8)
            dpg.add_raw_texture(rw, rh, self.tex_array, format=dpg.mvFormat_Float_rgba, tag=self.tag,
                                parent="texture_registry")
        return old

    def show(self, w: int, h: int, rw: int, rh: int, background, drawlist: str) -> bool:
        """Show the view at ``w`` x ``h`` pixels in ``drawlist``, from a new texture of ``rw`` x ``rh``
        texels; True when the image item was made now (the first time)."""
        dpg = self.dpg
        old = self.remake(rw, rh, background)
        dpg.configure_item(drawlist, width=w, height=h)
        made = not dpg.does_item_exist("vp_image")
        if made:
            dpg.draw_image(self.tag, (0, 0), (w, h), uv_min=(0, 1), uv_max=(1, 0), tag="vp_image", parent=drawlist)
        else:
            dpg.configure_item("vp_image", texture_tag=self.tag, pmax=(w, h))
        self.drop(old)
        return made

    def drop(self, old: tuple) -> None:
        tag, shared = old
        if shared is not None:
            shared.release()
        if tag is not None:
            self.dpg.delete_item(tag)

    def give_up_shared(self, why: str) -> None:
        """Read the view back from now on (``why``: shown in the stats); the owner remakes the texture
        as a raw texture on its next update (``remake_due``)."""
        self.readback_why = why
        if self._shared is not None:
            self._shared.release()
            self._shared = None
        self.remake_due = True

    def finish(self) -> None:
        """Put the picture the renderer drew into the texture dearpygui shows: a copy on the GPU into
        dearpygui's own texture, or (readback path) a read into the raw texture's array. Does nothing
        when nothing new was rendered."""
        shared = self._shared
        found = False
        if shared is not None and shared.fbo is None:
            # also on frames that drew nothing new: the last picture is still in the renderer's framebuffer
            try:
                if shared.tries == 0 and self.unread:
                    self._fill_new_texture(shared.marker_row)
                found = shared.find()
                if not found and shared.tries >= self.SHARED_TEXTURE_TRIES:
                    self.give_up_shared(f"dearpygui's texture not found in {shared.tries} frames")
            except Exception as e:      # a GL error while looking: read back instead
                self.give_up_shared(f"dearpygui's texture not usable: {e}")
        if not (self.unread or found):
            return
        self.unread = False
        t1 = time.perf_counter()
        if self._shared is not None and self._shared.fbo is not None:
            self.gl.copy_framebuffer(self._shared.fbo, self.renderer.fbo)
        elif self.tex_array is not None:
            self.read_view(self._read_bytes, self.tex_array)
        if self._screen_fbo is None:     # dearpygui's own framebuffer: the same one every frame
            self._screen_fbo = self.gl.detect_framebuffer(0)
        self._screen_fbo.use()
        self.readback_ms = (time.perf_counter() - t1) * 1e3

    def _fill_new_texture(self, marker_row: np.ndarray) -> None:
        """The static texture added this frame is made by dearpygui later in the frame, from its value:
        make that value this frame's picture (read back once, with the marker in its first texels), so
        a new texture (a resize, a window being dragged) never shows an empty view."""
        image = self.read_view()
        image[0, :len(marker_row)] = marker_row
        self.dpg.set_value(self.tag, image.ravel())

    def read_view(self, byte_buf: np.ndarray | None = None, out: np.ndarray | None = None) -> np.ndarray:
        """The rendered view as float32 RGBA in 0..1, OpenGL's row order (into ``out`` when given, via
        ``byte_buf``). Bytes read and scaled here: several times cheaper than the driver's float read on
        software GL, and the same numbers (x * float32(1/255) is what llvmpipe computes)."""
        pixels = self.renderer.read(dtype=np.uint8, out=byte_buf, flip=False)
        return np.multiply(pixels, BYTE_TO_UNIT, out=out, dtype=np.float32)
