"""The 3D view's camera and the mouse input that moves it.

Mouse on the image: left-drag orbits, right/middle-drag pans, wheel zooms. The camera follows the
characters unless "Follow" is off (a pan turns it off). The camera's azimuth has one owner, the input
layer (sticks and keys move the characters relative to it): a left drag asks it to turn
(``orbit_camera``) and the camera takes the view's ``camera_azimuth`` each frame; pitch, distance and
target are the camera's own.
"""
from __future__ import annotations

import math

import numpy as np

#: a mouse button's name -> dearpygui's constant's name
_BUTTONS = {"left": "mvMouseButton_Left", "right": "mvMouseButton_Right", "middle": "mvMouseButton_Middle"}


def yaw_deg_from_azimuth(azimuth: float) -> float:
    """The orbit camera's yaw for an input-layer azimuth (radians; 0 looks along +Z)."""
    return float(np.degrees(azimuth - np.pi)) % 360.0


def focus_radius(distance: float, fov_y_deg: float) -> float:
    """How far (m, on the ground) the followed point may be from the inspected character: a third of
    the half-height the view shows at the target's distance (the character stays in the middle third)."""
    return float(distance) * math.tan(math.radians(fov_y_deg) / 2.0) / 3.0


def drawn_root(drawn: dict, name: str):
    """Where character ``name``'s root is drawn (its side-by-side shift added), or None."""
    root = drawn["roots"].get(name)
    if root is None:
        return None
    off = drawn["offsets"].get(name, (0.0, 0.0, 0.0))
    return [root[i] + off[i] for i in range(3)]


def pull_towards(point: list, focus: list, radius: float) -> list:
    """``point`` moved horizontally (x, z) to within ``radius`` of ``focus``."""
    dx, dz = point[0] - focus[0], point[2] - focus[2]
    d = math.hypot(dx, dz)
    if d <= radius:
        return point
    k = radius / d
    return [focus[0] + dx * k, point[1], focus[2] + dz * k]


class CameraControl:
    """The orbit camera of the 3D view, dragged, scrolled and following the characters."""

    def __init__(self, viewer, dpg, orbit_camera, drawlist: str, follow_checkbox: str):
        self.viewer, self.dpg = viewer, dpg
        self.orbit_camera = orbit_camera            # turns the input layer's azimuth by radians
        self.drawlist, self.follow_checkbox = drawlist, follow_checkbox
        self.camera = viewer.OrbitCamera(target=np.array([0.8, 0.8, 0.0]), distance=4.6, yaw_deg=35.0,
                                         pitch_deg=16.0)
        self.follow = True
        self.drag = None               # the button being dragged with ("left", "right", "middle"), or None
        self.last_mouse = None
        self.wheel = 0.0

    def set_follow(self, on: bool) -> None:
        self.follow = bool(on)
        self.dpg.set_value(self.follow_checkbox, self.follow)

    def on_wheel(self, delta: float) -> None:
        if self.dpg.is_item_hovered(self.drawlist):
            self.wheel += float(delta)

    def mouse(self, height_px: int) -> None:
        """Apply this frame's drag and wheel to the camera (``height_px``: the image's height, which a
        pan's speed is relative to)."""
        dpg = self.dpg
        mouse = dpg.get_mouse_pos(local=False)
        if self.drag is None:
            # a drag starts with a button down over the view (hovering is asked only then: a query of
            # an item costs tens of microseconds)
            down = next((name for name, b in _BUTTONS.items() if dpg.is_mouse_button_down(getattr(dpg, b))), None)
            if down is not None and dpg.is_item_hovered(self.drawlist):
                self.drag = down
                self.last_mouse = mouse
        else:
            if not dpg.is_mouse_button_down(getattr(dpg, _BUTTONS[self.drag])):
                self.drag = None
            else:
                dx, dy = mouse[0] - self.last_mouse[0], mouse[1] - self.last_mouse[1]
                self.last_mouse = mouse
                if dx or dy:
                    if self.drag == "left":
                        # the input layer owns the azimuth (sticks are camera relative): ask it to turn
                        self.orbit_camera(float(np.radians(-dx * 0.4)))
                        self.camera.orbit(0.0, dy)
                    else:
                        self.viewer.apply_drag(self.camera, self.drag, dx, dy, max(height_px, 1))
                    if self.drag != "left":
                        self.set_follow(False)
        if self.wheel:
            self.viewer.apply_scroll(self.camera, self.wheel)
            self.wheel = 0.0

    def aim(self, azimuth: float, roots: list, live: bool, focus=None) -> None:
        """The camera's yaw from the input layer's ``azimuth``; when following, its target moves towards
        the mean of ``roots`` (what should stay in view), at once when not live (a picked tick). With
        ``focus`` (the inspected character's root, as drawn) the target stays within
        :func:`focus_radius` of it, so zoomed in during a sideways run, where the figures drift apart,
        the inspected one stays near the middle and the others may leave the picture."""
        self.camera.yaw_deg = yaw_deg_from_azimuth(azimuth)
        if roots and self.follow:
            n = len(roots)     # their mean, in plain floats (numpy's mean of a few rows costs 10-20 us)
            centre = [sum(float(r[i]) for r in roots) / n for i in range(3)]
            if focus is not None:
                centre = pull_towards(centre, [float(x) for x in focus],
                                      focus_radius(self.camera.distance, self.camera.fov_y_deg))
            self.camera.follow(centre, blend=0.12 if live else 1.0)

    def key(self) -> tuple:
        """What of the camera the picture depends on (see ``ViewportPanel._scene_key``)."""
        cam = self.camera
        t = cam.target
        return (float(t[0]), float(t[1]), float(t[2]), cam.distance, cam.yaw_deg, cam.pitch_deg, cam.fov_y_deg)

    def state(self) -> dict:
        return {"target": [float(x) for x in self.camera.target], "yaw_deg": self.camera.yaw_deg,
                "distance": self.camera.distance}
