"""A glfw window playing an animation: the standalone BVH player.

Keys: space pause, left/right step a frame (shift: 10), [ ] slower/faster, F follow the root,
R reframe, C capsules/sticks, S shadow on/off, Home restart, Esc/Q quit. Mouse: left-drag orbit,
right/middle-drag pan, wheel zoom.
"""
from __future__ import annotations

import time

import glfw
import moderngl
import numpy as np

from .camera import apply_drag, apply_scroll
from .player import AnimationView, Playback
from .renderer import Renderer


class WindowError(RuntimeError):
    """The window or its OpenGL context could not be created."""


_BUTTONS = {glfw.MOUSE_BUTTON_LEFT: "left", glfw.MOUSE_BUTTON_RIGHT: "right",
            glfw.MOUSE_BUTTON_MIDDLE: "middle"}


class PlayerWindow:
    """Owns the glfw window, the moderngl context on it, the renderer and the playback state."""

    def __init__(self, parents, positions, frame_time: float, title: str = "lmm-studio view",
                 width: int = 1280, height: int = 720, samples: int | None = None, start_frame: int = 0,
                 names=None, style: str = "capsules", shadow: bool = True, body_radii=None):
        try:
            ok = glfw.init()
        except Exception as e:  # pyGLFW may raise instead of returning False
            raise WindowError(f"cannot initialise glfw (no display?): {e}") from e
        if not ok:
            raise WindowError("cannot initialise glfw (no display?)")
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
        self.window = glfw.create_window(int(width), int(height), title, None, None)
        if not self.window:
            glfw.terminate()
            raise WindowError("cannot create a window with an OpenGL 3.3 core context")
        glfw.make_context_current(self.window)
        glfw.swap_interval(1)
        self.ctx = moderngl.create_context(require=330)
        fb_w, fb_h = glfw.get_framebuffer_size(self.window)
        self.renderer = Renderer(self.ctx, fb_w, fb_h, samples=samples)
        self.screen = self.ctx.detect_framebuffer(0)
        self.view = AnimationView(self.ctx, parents, positions, aspect=fb_w / fb_h, names=names, style=style,
                                  shadow=shadow, body_radii=body_radii)
        self.playback = Playback(len(self.view.positions), float(frame_time))
        self.playback.seek(start_frame)
        self.view.reset_camera(self.playback.frame)
        self.title = title
        self._drag_button = None
        self._last_cursor = None
        self._fps = 0.0
        self._last_title_time = 0.0
        glfw.set_key_callback(self.window, self._on_key)
        glfw.set_mouse_button_callback(self.window, self._on_mouse_button)
        glfw.set_cursor_pos_callback(self.window, self._on_cursor)
        glfw.set_scroll_callback(self.window, self._on_scroll)
        glfw.set_framebuffer_size_callback(self.window, self._on_resize)

    # ---- input ---------------------------------------------------------------------------------
    def _on_key(self, window, key, scancode, action, mods):
        if action not in (glfw.PRESS, glfw.REPEAT):
            return
        pb, view = self.playback, self.view
        step = 10 if mods & glfw.MOD_SHIFT else 1
        if key == glfw.KEY_SPACE and action == glfw.PRESS:
            pb.paused = not pb.paused
        elif key == glfw.KEY_RIGHT:
            pb.step(step)
        elif key == glfw.KEY_LEFT:
            pb.step(-step)
        elif key == glfw.KEY_RIGHT_BRACKET:
            pb.faster()
        elif key == glfw.KEY_LEFT_BRACKET:
            pb.slower()
        elif key == glfw.KEY_F and action == glfw.PRESS:
            view.follow = not view.follow
        elif key == glfw.KEY_R and action == glfw.PRESS:
            view.reset_camera(pb.frame)
        elif key == glfw.KEY_C and action == glfw.PRESS:
            view.skeleton.style = "sticks" if view.skeleton.style == "capsules" else "capsules"
        elif key == glfw.KEY_S and action == glfw.PRESS:
            view.skeleton.shadow = not view.skeleton.shadow
        elif key == glfw.KEY_HOME:
            pb.seek(0)
        elif key in (glfw.KEY_ESCAPE, glfw.KEY_Q):
            glfw.set_window_should_close(window, True)

    def _on_mouse_button(self, window, button, action, mods):
        if action == glfw.PRESS and button in _BUTTONS:
            self._drag_button = _BUTTONS[button]
            self._last_cursor = glfw.get_cursor_pos(window)
        elif action == glfw.RELEASE and _BUTTONS.get(button) == self._drag_button:
            self._drag_button = None

    def _on_cursor(self, window, x, y):
        if self._drag_button is None or self._last_cursor is None:
            return
        dx, dy = x - self._last_cursor[0], y - self._last_cursor[1]
        self._last_cursor = (x, y)
        apply_drag(self.view.camera, self._drag_button, dx, dy, max(glfw.get_window_size(window)[1], 1))

    def _on_scroll(self, window, xoffset, yoffset):
        apply_scroll(self.view.camera, yoffset)

    def _on_resize(self, window, width, height):
        if width > 0 and height > 0:
            self.renderer.resize(width, height)
            self.view.aspect = width / height
            self.ctx.viewport = (0, 0, width, height)
            self.screen = self.ctx.detect_framebuffer(0)

    # ---- loop ----------------------------------------------------------------------------------
    def draw(self) -> None:
        self.view.set_frame(self.playback.frame)
        self.renderer.render_to(self.view.scene, self.view.camera, target=self.screen)

    def screenshot(self) -> np.ndarray:
        """The window's current back buffer as an (H, W, 3) uint8 image, row 0 at the top."""
        w, h = self.screen.width, self.screen.height
        data = self.screen.read(components=3)
        return np.frombuffer(data, dtype=np.uint8).reshape(h, w, 3)[::-1].copy()

    def _update_title(self, now: float) -> None:
        if now - self._last_title_time < 0.5:
            return
        self._last_title_time = now
        pb = self.playback
        state = "paused" if pb.paused else f"x{pb.speed:g}"
        follow = "follow" if self.view.follow else "free"
        glfw.set_window_title(self.window, f"{self.title} | frame {pb.frame}/{pb.n_frames - 1} | {state} | "
                                           f"{follow} | {self._fps:.0f} fps")

    def run(self, max_frames: int | None = None, screenshot_path: str | None = None, save_image=None) -> int:
        """Play until the window closes (or ``max_frames`` frames were shown, then optionally hand the
        window's framebuffer, an ``(H, W, 3)`` uint8 array, to ``save_image(screenshot_path, image)``: the
        caller's PNG writer, since the viewer writes no files)."""
        last = time.perf_counter()
        shown = 0
        try:
            while not glfw.window_should_close(self.window):
                glfw.poll_events()
                now = time.perf_counter()
                dt, last = now - last, now
                if dt > 0:
                    self._fps = 0.9 * self._fps + 0.1 / dt if self._fps else 1.0 / dt
                self.playback.advance(min(dt, 0.25))
                self.draw()
                shown += 1
                if max_frames is not None and shown >= max_frames:
                    if screenshot_path and save_image is not None:
                        save_image(screenshot_path, self.screenshot())
                    break
                glfw.swap_buffers(self.window)
                self._update_title(now)
        finally:
            self.close()
        return 0

    def close(self) -> None:
        if self.window is not None:
            self.view.scene.release()
            self.renderer.release()
            glfw.destroy_window(self.window)
            self.window = None
            glfw.terminate()
