"""Gamepads through glfw's gamepad API (pyGLFW).

glfw remaps every pad it has an SDL mapping for (Xbox, PlayStation, Switch Pro and many more) onto
one layout, so all of them come out as the same :class:`~app.input.state.GamepadState`.

This uses pyGLFW's own GLFW library, which is a separate instance from the GLFW that dearpygui
links statically, so it calls ``glfw.init()`` itself; when that fails (no display) gamepads through
glfw are simply unavailable. Calling ``init`` again when someone else in the process already
initialised pyGLFW's library is harmless; :meth:`GlfwGamepads.close` does not terminate glfw unless
asked to (that would destroy the other user's windows). Call from the main thread (a GLFW rule).

glfw's stick y axes point down and its trigger axes rest at -1; both are converted here.
"""
from __future__ import annotations

import warnings
from contextlib import contextmanager
from dataclasses import dataclass

from .state import GamepadState, dpad_to_hat

MAX_JOYSTICKS = 16   # GLFW_JOYSTICK_1 .. GLFW_JOYSTICK_LAST
TRIGGER_BUTTON_THRESHOLD = 0.5

# glfw gamepad button index -> canonical name (GLFW_GAMEPAD_BUTTON_A .. _DPAD_LEFT)
GLFW_BUTTONS = ("south", "east", "west", "north", "l1", "r1", "select", "start", "home", "l3", "r3",
                "dpad_up", "dpad_right", "dpad_down", "dpad_left")
AXIS_LEFT_X, AXIS_LEFT_Y, AXIS_RIGHT_X, AXIS_RIGHT_Y, AXIS_LEFT_TRIGGER, AXIS_RIGHT_TRIGGER = range(6)


def _import_glfw():
    try:
        import glfw
        return glfw
    except Exception:
        return None


def _float(v) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return 0.0
    return f if f == f else 0.0   # NaN -> 0


def _clamp(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else hi if v > hi else v


def state_from_glfw(raw) -> GamepadState | None:
    """``glfw.get_gamepad_state`` result (``.buttons`` 15 ints, ``.axes`` 6 floats) -> state, or None if malformed."""
    try:
        buttons, axes = list(raw.buttons), [_float(a) for a in raw.axes]
    except Exception:
        try:
            buttons, axes = list(raw[0]), [_float(a) for a in raw[1]]
        except Exception:
            return None
    if len(axes) < 6 or len(buttons) < len(GLFW_BUTTONS):
        return None
    held = {name for name, b in zip(GLFW_BUTTONS, buttons) if b}
    lt = _clamp((axes[AXIS_LEFT_TRIGGER] + 1.0) * 0.5, 0.0, 1.0)
    rt = _clamp((axes[AXIS_RIGHT_TRIGGER] + 1.0) * 0.5, 0.0, 1.0)
    if lt > TRIGGER_BUTTON_THRESHOLD:
        held.add("l2")
    if rt > TRIGGER_BUTTON_THRESHOLD:
        held.add("r2")
    hat = dpad_to_hat("dpad_up" in held, "dpad_down" in held, "dpad_left" in held, "dpad_right" in held)
    return GamepadState(left_x=_clamp(axes[AXIS_LEFT_X], -1.0, 1.0), left_y=_clamp(-axes[AXIS_LEFT_Y], -1.0, 1.0),
                        right_x=_clamp(axes[AXIS_RIGHT_X], -1.0, 1.0), right_y=_clamp(-axes[AXIS_RIGHT_Y], -1.0, 1.0),
                        left_trigger=lt, right_trigger=rt, buttons=frozenset(held), hat=hat)


def guid_vendor_product(guid) -> tuple[int, int] | None:
    """USB vendor and product ids from a GLFW (SDL-format) joystick GUID, when it carries them.

    The GUID is 16 bytes in hex: little-endian 16-bit bus type, 0, vendor, 0, product, 0, version, 0.
    Other GUID formats (e.g. XInput's) give None.
    """
    if isinstance(guid, bytes):
        guid = guid.decode("ascii", "replace")
    if not isinstance(guid, str) or len(guid) != 32:
        return None
    try:
        b = bytes.fromhex(guid)
    except ValueError:
        return None
    if b[2:4] != b"\0\0" or b[6:8] != b"\0\0" or b[10:12] != b"\0\0":
        return None
    vendor, product = int.from_bytes(b[4:6], "little"), int.from_bytes(b[8:10], "little")
    return (vendor, product) if vendor else None


@dataclass(frozen=True)
class GlfwPad:
    jid: int
    name: str
    guid: str
    vendor_product: tuple[int, int] | None


class GlfwGamepads:
    """Polls every glfw joystick slot that has a gamepad mapping. ``poll()`` never raises.

    ``glfw_module``: the ``glfw`` module (default, imported lazily) or a stand-in with ``init``,
    ``joystick_present``, ``joystick_is_gamepad``, ``get_gamepad_state``, ``get_gamepad_name`` and
    optionally ``get_joystick_guid`` and ``poll_events``. ``None`` disables glfw gamepads.
    ``poll_events``: call ``glfw.poll_events()`` each poll, which lets GLFW notice pads plugged in
    after start-up on platforms that report it through events (pyGLFW's instance has no windows, so
    this touches nothing of dearpygui's).
    """

    def __init__(self, glfw_module="auto", init: bool = True, poll_events: bool = True,
                 terminate_on_close: bool = False):
        self._glfw = _import_glfw() if glfw_module == "auto" else glfw_module
        self._poll_events = bool(poll_events)
        self._terminate_on_close = bool(terminate_on_close)
        self.available = False
        self.error = ""
        self.pads: dict[int, GlfwPad] = {}
        self.states: dict[int, GamepadState] = {}
        self.events: list[str] = []
        if self._glfw is None:
            self.error = "glfw not importable" if glfw_module == "auto" else "disabled"
            return
        if init:
            messages: list[str] = []
            try:
                with self._quiet(messages):
                    ok = self._glfw.init()
            except Exception as e:
                ok, self.error = False, f"glfw.init failed: {e}"
            self.available = bool(ok)
            if not ok and not self.error:
                self.error = "glfw.init failed" + (f": {messages[-1]}" if messages else " (no display?)")
        else:
            self.available = True

    @contextmanager
    def _quiet(self, messages: list | None = None):
        """Keep pyGLFW's error warnings (its default ERROR_REPORTING is 'warn') out of the console during
        our calls; their texts go to ``messages`` when given."""
        category = getattr(self._glfw, "GLFWError", None)
        if isinstance(category, type) and issubclass(category, Warning):
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", category)
                yield
            for w in caught:
                if issubclass(w.category, category):
                    if messages is not None:
                        messages.append(str(w.message))
                else:   # not ours to swallow
                    warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        else:
            yield

    def poll(self) -> dict[int, GamepadState]:
        """Current states of connected gamepads, by joystick id. Pads that vanished are dropped."""
        if not self.available:
            return {}
        try:
            with self._quiet():
                self._poll()
        except Exception as e:   # pyGLFW raises GLFWError when ERROR_REPORTING is 'raise'
            self.error = f"poll: {e}"
            self._drop_all(f"error: {e}")
        return dict(self.states)

    def _drop_all(self, why: str) -> None:
        for pad in self.pads.values():
            self.events.append(f"disconnected: {pad.name} ({why})")
        self.pads.clear()
        self.states.clear()

    def _poll(self) -> None:
        g = self._glfw
        if self._poll_events and hasattr(g, "poll_events"):
            try:
                g.poll_events()
            except Exception:
                pass
        seen = set()
        for jid in range(MAX_JOYSTICKS):
            try:
                present = g.joystick_present(jid) and g.joystick_is_gamepad(jid)
                raw = g.get_gamepad_state(jid) if present else None
            except Exception:
                present, raw = False, None
            st = state_from_glfw(raw) if raw is not None else None
            if st is None:
                continue
            seen.add(jid)
            self.states[jid] = st
            if jid not in self.pads:
                self.pads[jid] = self._describe(jid)
                self.events.append(f"connected: {self.pads[jid].name}")
        for jid in [j for j in self.pads if j not in seen]:
            self.events.append(f"disconnected: {self.pads[jid].name}")
            del self.pads[jid]
            self.states.pop(jid, None)

    def _describe(self, jid: int) -> GlfwPad:
        g = self._glfw
        name, guid = "", ""
        try:
            name = g.get_gamepad_name(jid) or ""
        except Exception:
            pass
        if isinstance(name, bytes):
            name = name.decode("utf-8", "replace")
        try:
            guid = g.get_joystick_guid(jid) if hasattr(g, "get_joystick_guid") else ""
        except Exception:
            guid = ""
        if isinstance(guid, bytes):
            guid = guid.decode("ascii", "replace")
        return GlfwPad(jid, f"{name or 'Gamepad'} (glfw #{jid})", guid or "", guid_vendor_product(guid))

    def close(self) -> None:
        self._drop_all("closed")
        if self._terminate_on_close and self.available:
            try:
                with self._quiet():
                    self._glfw.terminate()
            except Exception:
                pass
        self.available = False

