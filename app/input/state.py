"""A gamepad's state in one layout, whatever the backend (glfw's SDL mapping or a raw HID report).

Buttons are named by position so Xbox, PlayStation and Switch pads read alike:
``south`` (Xbox A / PlayStation cross), ``east`` (B / circle), ``west`` (X / square),
``north`` (Y / triangle), ``l1``/``r1`` (shoulders), ``l2``/``r2`` (triggers pressed),
``l3``/``r3`` (stick clicks), ``select`` (Back / Share / Create), ``start`` (Start / Options),
``home`` (Guide / PS), ``touchpad``, ``mute`` and ``dpad_up``/``dpad_down``/``dpad_left``/``dpad_right``.
:meth:`GamepadState.pressed` also accepts the usual aliases (``'cross'``, ``'a'``, ``'options'``, ``'ps'``...).

Sticks are in [-1, 1] with x right and y up (pushed away from the player), the convention of
:class:`lmm.controller.InputState`. Triggers are in [0, 1].
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

BUTTONS = ("south", "east", "west", "north", "l1", "r1", "l2", "r2", "l3", "r3",
           "select", "start", "home", "touchpad", "mute",
           "dpad_up", "dpad_down", "dpad_left", "dpad_right")

BUTTON_ALIASES = {
    # PlayStation labels
    "cross": "south", "circle": "east", "square": "west", "triangle": "north",
    "share": "select", "create": "select", "options": "start", "ps": "home",
    # Xbox labels
    "a": "south", "b": "east", "x": "west", "y": "north", "back": "select", "view": "select",
    "menu": "start", "guide": "home", "xbox": "home", "lb": "l1", "rb": "r1", "lt": "l2", "rt": "r2",
    "ls": "l3", "rs": "r3", "left_bumper": "l1", "right_bumper": "r1", "left_thumb": "l3", "right_thumb": "r3",
    # Nintendo labels (by position, as SDL's mappings do)
    "zl": "l2", "zr": "r2", "minus": "select", "plus": "start",
    "up": "dpad_up", "down": "dpad_down", "left": "dpad_left", "right": "dpad_right",
}

# hat switch value (0 = north, clockwise in 45 degree steps; anything else = centred) -> (x, y), y up
HAT_DIRECTIONS = {0: (0, 1), 1: (1, 1), 2: (1, 0), 3: (1, -1), 4: (0, -1), 5: (-1, -1), 6: (-1, 0), 7: (-1, 1)}
HAT_CENTRED = 8


def canonical_button(name: str) -> str:
    """``'Cross'`` -> ``'south'``; unknown names come back lower-cased."""
    n = str(name).strip().lower()
    return BUTTON_ALIASES.get(n, n)


def hat_to_dpad(hat: int) -> tuple[int, int]:
    """Hat switch value -> (x, y) with y up; (0, 0) when centred."""
    return HAT_DIRECTIONS.get(int(hat), (0, 0))


def hat_buttons(hat: int) -> set[str]:
    """The dpad button names held for a hat switch value."""
    x, y = hat_to_dpad(hat)
    out = set()
    if y > 0:
        out.add("dpad_up")
    if y < 0:
        out.add("dpad_down")
    if x < 0:
        out.add("dpad_left")
    if x > 0:
        out.add("dpad_right")
    return out


def dpad_to_hat(up: bool, down: bool, left: bool, right: bool) -> int:
    """Four dpad buttons -> hat switch value (opposite directions cancel)."""
    x = int(bool(right)) - int(bool(left))
    y = int(bool(up)) - int(bool(down))
    for hat, d in HAT_DIRECTIONS.items():
        if d == (x, y):
            return hat
    return HAT_CENTRED


def clamp_unit_disc(x: float, y: float) -> tuple[float, float]:
    """Scale (x, y) down onto the unit disc if it lies outside (square stick gates reach ~1.4)."""
    x, y = float(x), float(y)
    if not (math.isfinite(x) and math.isfinite(y)):
        return 0.0, 0.0
    m = math.hypot(x, y)
    if m > 1.0:
        return x / m, y / m
    return x, y


def radial_deadzone(x: float, y: float, deadzone: float) -> tuple[float, float]:
    """Zero inside ``deadzone``; outside, rescaled so the edge of the deadzone is 0 and full tilt is 1."""
    x, y = clamp_unit_disc(x, y)
    m = math.hypot(x, y)
    if m <= deadzone or m <= 0.0:
        return 0.0, 0.0
    s = min((m - deadzone) / max(1.0 - deadzone, 1e-6), 1.0) / m
    return x * s, y * s


@dataclass(frozen=True)
class GamepadState:
    """One reading of one gamepad."""
    left_x: float = 0.0
    left_y: float = 0.0
    right_x: float = 0.0
    right_y: float = 0.0
    left_trigger: float = 0.0    # [0, 1]
    right_trigger: float = 0.0   # [0, 1]
    buttons: frozenset = field(default_factory=frozenset)  # canonical names (see BUTTONS)
    hat: int = HAT_CENTRED       # 0..7 clockwise from north, 8 = centred

    def pressed(self, name: str) -> bool:
        """Is this button held? Accepts canonical names and aliases (``'cross'``, ``'a'``, ``'ps'``...)."""
        return canonical_button(name) in self.buttons

    @property
    def dpad(self) -> tuple[int, int]:
        return hat_to_dpad(self.hat)

    @property
    def left_stick(self) -> tuple[float, float]:
        return self.left_x, self.left_y

    @property
    def right_stick(self) -> tuple[float, float]:
        return self.right_x, self.right_y
