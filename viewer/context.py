"""Getting a moderngl context: headless (EGL, no display needed) or attached to the current one."""
from __future__ import annotations

import moderngl

MIN_GL_VERSION = 330


class ContextError(RuntimeError):
    """No usable OpenGL context; the message says why and what to try."""


def create_headless_context(require: int = MIN_GL_VERSION) -> moderngl.Context:
    """A standalone EGL context for tests, screenshots and benchmarks; needs no X server.

    Raises ContextError with a readable message when EGL (libEGL + a Mesa or GPU driver) is not
    available.
    """
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=require)
    except Exception as e:  # glcontext raises plain Exceptions with the loader's message
        raise ContextError(
            f"cannot create a headless OpenGL {require // 100}.{require % 100 // 10} context with EGL: {e}. "
            "Install libegl1 and a Mesa driver (e.g. libegl-mesa0) or a GPU driver with EGL support."
        ) from e
    return ctx


def attach_current_context(require: int = MIN_GL_VERSION) -> moderngl.Context:
    """Wrap the OpenGL context that is current on this thread (a glfw window's, or dearpygui's
    after its first ``render_dearpygui_frame()``). Everything the viewer creates then lives in
    that context; draw into a Renderer's framebuffer and read it back, and the renderer restores
    the previously bound framebuffer afterwards."""
    try:
        return moderngl.create_context(require=require)
    except Exception as e:
        raise ContextError(f"no current OpenGL {require // 100}.{require % 100 // 10} context to attach to: {e}") from e
