"""The 3D view drawn straight into the OpenGL texture dearpygui shows (no readback, no upload).

dearpygui takes images only as float arrays: a raw texture is copied and converted to the GPU's format
on every frame (on software OpenGL that upload costs about as much as drawing the whole scene), and the
3D view would first have to read its pixels back to fill it. dearpygui has no call that hands over an
existing OpenGL texture, but its static textures are ordinary ``GL_TEXTURE_2D`` objects of the one
context the studio shares with moderngl, made on the frame after ``add_static_texture`` and never
written by dearpygui again. :class:`SharedTexture` finds that texture's OpenGL name and wraps it in a
moderngl framebuffer, so each frame the rendered view is copied into it on the GPU.

Finding the name: the OpenGL names alive before the texture is added are listed (``glIsTexture``, an
OpenGL 1.1 entry point the system's GL library exports), then, once dearpygui has made it, the new names
whose level 0 has the texture's size are candidates, and the one holding the marker the texture was
filled with is it. Anything that does not fit (no GL library, no new name of that size, a different
marker) leaves the caller on the readback path, with the reason.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import sys

import numpy as np

_GL_TEXTURE_2D = 0x0DE1
_GL_TEXTURE_BINDING_2D = 0x8069
_GL_TEXTURE_WIDTH = 0x1000
_GL_TEXTURE_HEIGHT = 0x1001
#: marker texels: the first ``MARKER_TEXELS`` of the bottom row (OpenGL's row 0)
MARKER_TEXELS = 64
#: names scanned above the newest one moderngl can make, for textures made in between
SCAN_MARGIN = 512


def _load_gl():
    """The system OpenGL library's OpenGL 1.1 functions (ctypes), or None with the reason."""
    if sys.platform.startswith("win"):
        names = ["opengl32"]
    else:
        names = ["libGL.so.1", ctypes.util.find_library("GL")]
    for name in names:
        if not name:
            continue
        try:
            lib = ctypes.WinDLL(name) if sys.platform.startswith("win") else ctypes.CDLL(name)
        except OSError:
            continue
        lib.glIsTexture.restype = ctypes.c_ubyte
        lib.glIsTexture.argtypes = [ctypes.c_uint]
        return lib, ""
    return None, "no system OpenGL library to query texture names"


class TextureNames:
    """Query the current context's texture names (the system GL library's OpenGL 1.1 entry points)."""

    def __init__(self, lib):
        self.lib = lib

    def alive(self, upto: int) -> set[int]:
        is_texture = self.lib.glIsTexture
        return {n for n in range(1, upto + 1) if is_texture(n)}

    def size(self, name: int) -> tuple[int, int]:
        """Level 0's (width, height) of texture ``name``; the 2D binding is restored."""
        lib = self.lib
        prev, w, h = ctypes.c_int(), ctypes.c_int(), ctypes.c_int()
        lib.glGetIntegerv(_GL_TEXTURE_BINDING_2D, ctypes.byref(prev))
        lib.glBindTexture(_GL_TEXTURE_2D, ctypes.c_uint(name))
        lib.glGetTexLevelParameteriv(_GL_TEXTURE_2D, 0, _GL_TEXTURE_WIDTH, ctypes.byref(w))
        lib.glGetTexLevelParameteriv(_GL_TEXTURE_2D, 0, _GL_TEXTURE_HEIGHT, ctypes.byref(h))
        lib.glBindTexture(_GL_TEXTURE_2D, ctypes.c_uint(prev.value))
        return int(w.value), int(h.value)


def marker_image(width: int, height: int, background, seed: int) -> np.ndarray:
    """A float32 (height, width, 4) image of ``background`` whose first :data:`MARKER_TEXELS` texels of
    row 0 differ from it by a few 8-bit levels (invisible, and one frame only) in a pattern ``seed``
    picks."""
    img = np.empty((height, width, 4), np.float32)
    base = np.round(np.clip(np.asarray(background, np.float64), 0.0, 1.0) * 255.0)
    img[..., :3] = (base / 255.0).astype(np.float32)
    img[..., 3] = 1.0
    n = min(MARKER_TEXELS, width)
    levels = np.random.default_rng(seed).integers(0, 12, size=(n, 3))
    img[0, :n, :3] = (np.clip(base + levels, 0, 255) / 255.0).astype(np.float32)
    return img


class SharedTexture:
    """The OpenGL texture of one dearpygui static texture, as a moderngl framebuffer to copy into.

    Make it after ``add_static_texture(width, height, marker)`` (``marker``: :func:`marker_image`) and
    before the next frame; call :meth:`find` after each frame until it returns True (found) or raises
    (give up). ``fbo`` is then the framebuffer; :meth:`release` before dearpygui deletes the texture."""

    def __init__(self, gl, names: TextureNames, width: int, height: int, marker: np.ndarray):
        self.gl = gl
        self.names = names
        self.size = (int(width), int(height))
        n = min(MARKER_TEXELS, width)
        self.marker_row = marker[0, :n].copy()      # the marker texels (float32 RGBA), row 0
        self._expected = np.round(self.marker_row[:, :3] * 255.0).astype(np.int16)
        probe = gl.texture((1, 1), 4)       # the newest name this context hands out now
        self._upto = int(probe.glo) + SCAN_MARGIN
        probe.release()
        self._before = names.alive(self._upto)
        self.fbo = None
        self.texture = None
        self.tries = 0

    def find(self) -> bool:
        """Look for the texture dearpygui made since; True when found (``fbo`` set)."""
        if self.fbo is not None:
            return True
        self.tries += 1
        new = sorted(self.names.alive(self._upto) - self._before)
        for name in new:
            if self.names.size(name) != self.size:
                continue
            tex = self.gl.external_texture(name, self.size, 4, 0, "f1")
            row = np.frombuffer(tex.read(), np.uint8)[:len(self._expected) * 4].reshape(-1, 4)[:, :3]
            if np.abs(row.astype(np.int16) - self._expected).max() <= 1:
                self.texture = tex
                self.fbo = self.gl.framebuffer(color_attachments=[tex])
                return True
            tex.release()           # a wrapper only: the texture stays
        return False

    def release(self) -> None:
        """Drop the framebuffer and the wrapper (the OpenGL texture is dearpygui's and stays)."""
        if self.fbo is not None:
            self.fbo.release()
        if self.texture is not None:
            self.texture.release()
        self.fbo = self.texture = None


_GL = None


def texture_names():
    """A :class:`TextureNames` for the system GL library (loaded once), or (None, reason)."""
    global _GL
    if _GL is None:
        _GL = _load_gl()
    lib, why = _GL
    return (TextureNames(lib), "") if lib is not None else (None, why)
