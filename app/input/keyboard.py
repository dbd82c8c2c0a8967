"""Keyboard input by logical key name, with no GUI toolkit import.

The studio forwards its key events (``press(name)`` / ``release(name)``) or, more robustly, the set
of keys held this frame (``set_keys(names)``, which cannot leave a key stuck when a release event
is lost to a focus change). :data:`DEARPYGUI_KEYS` names the dearpygui constants for each logical
key so the studio can build its own code -> name table with :func:`build_key_lookup`.

Mapping (also in :data:`KEY_BINDINGS`, for the studio's help panel):

==============  =======================================================
W A S D         left stick (move): up, left, down, right
arrow keys      left stick as well
I J K L         right stick: up, left, down, right (aim while strafing)
Q / E           turn the camera left / right
Shift           walk
Ctrl            strafe
==============  =======================================================

Opposite keys cancel; a diagonal gives a unit-length stick (0.7071, 0.7071).
"""
from __future__ import annotations

import math
from typing import Callable, Iterable

# (keys, action, description): the table the studio can show
KEY_BINDINGS: tuple[tuple[str, str, str], ...] = (
    ("W / Up", "move_up", "move away from the camera (left stick up)"),
    ("S / Down", "move_down", "move towards the camera (left stick down)"),
    ("A / Left", "move_left", "move to the camera's left (left stick left)"),
    ("D / Right", "move_right", "move to the camera's right (left stick right)"),
    ("I", "aim_up", "right stick up (aim direction while strafing)"),
    ("K", "aim_down", "right stick down"),
    ("J", "aim_left", "right stick left; also turns the camera when not strafing"),
    ("L", "aim_right", "right stick right; also turns the camera when not strafing"),
    ("Q", "camera_left", "turn the camera left"),
    ("E", "camera_right", "turn the camera right"),
    ("Shift", "walk", "walk instead of run (hold)"),
    ("Ctrl", "strafe", "strafe: keep facing the camera / right stick direction (hold)"),
    ("Mouse drag", "camera_orbit", "orbit the camera"),
)

# action -> logical key names that trigger it
ACTION_KEYS: dict[str, tuple[str, ...]] = {
    "move_up": ("w", "up"),
    "move_down": ("s", "down"),
    "move_left": ("a", "left"),
    "move_right": ("d", "right"),
    "aim_up": ("i",),
    "aim_down": ("k",),
    "aim_left": ("j",),
    "aim_right": ("l",),
    "camera_left": ("q",),
    "camera_right": ("e",),
    "walk": ("shift",),
    "strafe": ("ctrl",),
}

# keys whose press makes the keyboard the active device (modifiers and camera keys do not, so
# Shift/Ctrl/Q/E can be combined with a gamepad)
STICK_KEYS = frozenset(k for a in ("move_up", "move_down", "move_left", "move_right",
                                   "aim_up", "aim_down", "aim_left", "aim_right") for k in ACTION_KEYS[a])

KEY_NAME_ALIASES = {
    "arrow_up": "up", "arrowup": "up", "uparrow": "up", "key_up": "up",
    "arrow_down": "down", "arrowdown": "down", "downarrow": "down", "key_down": "down",
    "arrow_left": "left", "arrowleft": "left", "leftarrow": "left", "key_left": "left",
    "arrow_right": "right", "arrowright": "right", "rightarrow": "right", "key_right": "right",
    "lshift": "shift", "rshift": "shift", "left_shift": "shift", "right_shift": "shift",
    "shift_l": "shift", "shift_r": "shift", "modshift": "shift",
    "control": "ctrl", "lctrl": "ctrl", "rctrl": "ctrl", "lcontrol": "ctrl", "rcontrol": "ctrl",
    "left_control": "ctrl", "right_control": "ctrl", "left_ctrl": "ctrl", "right_ctrl": "ctrl",
    "control_l": "ctrl", "control_r": "ctrl", "modctrl": "ctrl",
}

# logical key -> dearpygui constant names (looked up by the studio: this module never imports dearpygui)
DEARPYGUI_KEYS: dict[str, tuple[str, ...]] = {
    **{c: (f"mvKey_{c.upper()}",) for c in "wasdijklqe"},
    "up": ("mvKey_Up",), "down": ("mvKey_Down",), "left": ("mvKey_Left",), "right": ("mvKey_Right",),
    "shift": ("mvKey_LShift", "mvKey_RShift"),
    "ctrl": ("mvKey_LControl", "mvKey_RControl"),
}

# a command's shortcut key name (see app.command_registry.Command.shortcut) -> its dearpygui constant name
SHORTCUT_KEYS: dict[str, str] = {"Space": "mvKey_Spacebar", "Home": "mvKey_Home", ",": "mvKey_Comma",
                                 ".": "mvKey_Period", "F": "mvKey_F", "Ctrl+Z": "mvKey_Z", "Ctrl+Shift+Z": "mvKey_Z"}


def shortcut_modifiers(name: str) -> tuple[bool, bool] | None:
    """``(ctrl, shift)`` a chord shortcut (``"Ctrl+Shift+Z"``) needs held, exactly; None for a plain key,
    which acts whatever is held (Shift walks and Ctrl strafes while Space pauses)."""
    parts = name.split("+")[:-1] if len(name) > 1 else []
    return ("Ctrl" in parts, "Shift" in parts) if parts else None


def normalize_key_name(name) -> str:
    """``'LShift'`` -> ``'shift'``, ``'ArrowUp'`` -> ``'up'``, ``'W'`` -> ``'w'``."""
    n = str(name).strip().lower().replace(" ", "_").replace("-", "_")
    if n.startswith("mvkey_"):
        n = n[len("mvkey_"):]
    return KEY_NAME_ALIASES.get(n, n)


def build_key_lookup(resolve: Callable[[str], object]) -> dict:
    """Key code -> logical name, given ``resolve(constant_name) -> code or None``.

    With dearpygui: ``build_key_lookup(lambda c: getattr(dpg, c, None))``.
    """
    table = {}
    for name, constants in DEARPYGUI_KEYS.items():
        for c in constants:
            try:
                code = resolve(c)
            except Exception:
                code = None
            if code is not None:
                table[code] = name
    return table


def _axis(held: frozenset, negative: str, positive: str) -> float:
    return float(any(k in held for k in ACTION_KEYS[positive])) - float(any(k in held for k in ACTION_KEYS[negative]))


def _unit(x: float, y: float) -> tuple[float, float]:
    m = math.hypot(x, y)
    return (x / m, y / m) if m > 1.0 else (x, y)


class KeyboardInput:
    """Tracks held keys by logical name and turns them into sticks, walk, strafe and camera turning."""

    name = "Keyboard"

    def __init__(self):
        self._held: set[str] = set()
        self.enabled = True          # False (e.g. while a text field has focus): every output is neutral
        self.activity_count = 0      # +1 for each newly pressed stick key (see STICK_KEYS)

    # ---- feeding ------------------------------------------------------------------------------
    def press(self, name) -> None:
        key = normalize_key_name(name)
        if key not in self._held:
            self._held.add(key)
            if key in STICK_KEYS:
                self.activity_count += 1

    def release(self, name) -> None:
        self._held.discard(normalize_key_name(name))

    def set_keys(self, names: Iterable) -> None:
        """Replace the held set with ``names`` (the keys down this frame); new stick keys count as activity."""
        new = {normalize_key_name(n) for n in names}
        if any(k in STICK_KEYS for k in new - self._held):
            self.activity_count += 1
        self._held = new

    def release_all(self) -> None:
        """Forget every held key (call when the window loses focus)."""
        self._held.clear()

    # ---- reading ------------------------------------------------------------------------------
    @property
    def held(self) -> frozenset:
        return frozenset(self._held)

    def is_down(self, name) -> bool:
        return normalize_key_name(name) in self._held

    def _active_keys(self) -> frozenset:
        return frozenset(self._held) if self.enabled else frozenset()

    def left_stick(self) -> tuple[float, float]:
        h = self._active_keys()
        return _unit(_axis(h, "move_left", "move_right"), _axis(h, "move_down", "move_up"))

    def right_stick(self) -> tuple[float, float]:
        h = self._active_keys()
        return _unit(_axis(h, "aim_left", "aim_right"), _axis(h, "aim_down", "aim_up"))

    @property
    def walk(self) -> bool:
        return any(k in self._active_keys() for k in ACTION_KEYS["walk"])

    @property
    def strafe(self) -> bool:
        return any(k in self._active_keys() for k in ACTION_KEYS["strafe"])

    def camera_turn(self) -> float:
        """+1 while Q (turn left: the azimuth grows), -1 while E, 0 for both or neither."""
        h = self._active_keys()
        return _axis(h, "camera_right", "camera_left")

    def any_stick_key(self) -> bool:
        return any(k in STICK_KEYS for k in self._active_keys())
