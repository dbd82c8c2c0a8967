"""Whether the studio can open its window, asked before dearpygui is: dearpygui (GLFW) aborts the whole
process when the display named by ``DISPLAY`` is not there, or when no OpenGL context can be made on it
(an X server without GLX, a broken or missing driver: ``glfwSetWindowPos: Assertion 'window != NULL'
failed``, exit 134). A dead display is found here with Xlib, a display without OpenGL by making a small
context of our own on it (moderngl, GLX: it fails with an exception, not an abort); each is one line."""
from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys


def display_problem() -> str | None:
    """Why no window can be opened (one line), or None when the display answers (or cannot be asked)."""
    if not sys.platform.startswith("linux") or not os.environ.get("DISPLAY"):
        return None   # Wayland alone, macOS, Windows: nothing to ask here (no DISPLAY is checked apart)
    name = ctypes.util.find_library("X11")
    if name is None:
        return None
    try:
        xlib = ctypes.CDLL(name)
        xlib.XOpenDisplay.restype = ctypes.c_void_p
        xlib.XOpenDisplay.argtypes = [ctypes.c_char_p]
        xlib.XCloseDisplay.argtypes = [ctypes.c_void_p]
    except (OSError, AttributeError):
        return None
    handle = xlib.XOpenDisplay(None)
    if not handle:
        return (f"cannot open the display {os.environ['DISPLAY'][:40]!r} (DISPLAY): no X server answers there; "
                f"check DISPLAY, or run under Xvfb: xvfb-run -a lmm-studio ...")
    xlib.XCloseDisplay(handle)
    return gl_problem()


#: the OpenGL version dearpygui asks GLFW for on Linux
DEARPYGUI_GL = 300


def gl_problem() -> str | None:
    """Why no OpenGL context can be made on the display (one line), or None when one can (about 0.1 s)."""
    try:
        import moderngl
    except ImportError:
        return None
    sys.stderr.flush()
    saved = os.dup(2)   # Mesa prints its own "libGL error" lines: the one line below says it all
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 2)
        os.close(devnull)
        ctx = moderngl.create_standalone_context(require=DEARPYGUI_GL)
    except Exception as e:   # noqa: BLE001 - glcontext raises plain Exceptions with GLX's reason
        reason = " ".join(str(e).split())[:160]
        return (f"cannot create an OpenGL context on the display {os.environ['DISPLAY'][:40]!r} ({reason}): the X "
                f"server has no GLX, or the graphics driver cannot be loaded; check the driver (LIBGL_ALWAYS_SOFTWARE,"
                f" GALLIUM_DRIVER, MESA_LOADER_DRIVER_OVERRIDE), or run under xvfb-run -a, which has GLX")
    finally:
        os.dup2(saved, 2)
        os.close(saved)
    ctx.release()
    return None
