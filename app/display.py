"""Whether the studio can open its window, asked before dearpygui is: dearpygui (GLFW) aborts the whole
process when the display named by ``DISPLAY`` is not there (``glfwSetWindowPos: Assertion 'window !=
NULL' failed``, exit 134), so a dead display is found here with Xlib and reported in one line."""
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
    return None
