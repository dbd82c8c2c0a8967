"""Drive the player window's key handler under Xvfb and print the resulting state as JSON.

argv: folder holding viewer_testutil.py. Run by test_viewer_window.py.
"""
import json
import sys

import glfw
import numpy as np

from viewer.window import PlayerWindow

sys.path.insert(0, sys.argv[1])
from viewer_testutil import TPOSE_PARENTS, TPOSE_POSITIONS  # noqa: E402

frames = 50
positions = np.repeat(TPOSE_POSITIONS[None], frames, axis=0) + np.linspace(0, 2, frames)[:, None, None] * [1, 0, 0]
win = PlayerWindow(TPOSE_PARENTS, positions, 1 / 30, width=320, height=240)
state = {}
press = lambda key, mods=0: win._on_key(win.window, key, 0, glfw.PRESS, mods)  # noqa: E731
press(glfw.KEY_SPACE)
state["paused_after_space"] = win.playback.paused
press(glfw.KEY_RIGHT)
press(glfw.KEY_RIGHT)
state["frame_after_two_rights"] = win.playback.frame
press(glfw.KEY_LEFT, glfw.MOD_SHIFT)
state["frame_after_shift_left"] = win.playback.frame
speed = win.playback.speed
press(glfw.KEY_RIGHT_BRACKET)
state["faster"] = win.playback.speed > speed
press(glfw.KEY_LEFT_BRACKET)
press(glfw.KEY_LEFT_BRACKET)
state["slower"] = win.playback.speed < speed
follow = win.view.follow
press(glfw.KEY_F)
state["follow_toggled"] = win.view.follow != follow
style = win.view.skeleton.style
press(glfw.KEY_C)
state["style_toggled"] = [style, win.view.skeleton.style]
shadow = win.view.skeleton.shadow
press(glfw.KEY_S)
state["shadow_toggled"] = win.view.skeleton.shadow != shadow
distance = win.view.camera.distance
win._on_scroll(win.window, 0, 2)
state["zoomed_in"] = win.view.camera.distance < distance
yaw = win.view.camera.yaw_deg
win._on_mouse_button(win.window, glfw.MOUSE_BUTTON_LEFT, glfw.PRESS, 0)
x, y = win._last_cursor
win._on_cursor(win.window, x + 40, y)
win._on_mouse_button(win.window, glfw.MOUSE_BUTTON_LEFT, glfw.RELEASE, 0)
state["orbited"] = win.view.camera.yaw_deg != yaw
target = win.view.camera.target.copy()
win._on_mouse_button(win.window, glfw.MOUSE_BUTTON_RIGHT, glfw.PRESS, 0)
x, y = win._last_cursor
win._on_cursor(win.window, x + 30, y + 10)
state["panned"] = bool(np.abs(win.view.camera.target - target).max() > 0)
win._on_mouse_button(win.window, glfw.MOUSE_BUTTON_RIGHT, glfw.RELEASE, 0)
win._on_resize(win.window, 330, 250)
win.draw()
state["resized"] = win.renderer.size == (330, 250) and abs(win.view.aspect - 330 / 250) < 1e-9
press(glfw.KEY_ESCAPE)
state["closing"] = bool(glfw.window_should_close(win.window))
state["run_rc"] = win.run(max_frames=3)
print(json.dumps(state))
