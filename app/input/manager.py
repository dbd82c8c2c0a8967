"""One :class:`~lmm.controller.InputState` per frame from the keyboard and any gamepads.

Devices: the keyboard (always there), pads through glfw's gamepad API (:mod:`.glfw_gamepad`) and a
DualShock 4 / DualSense read through hidapi (:mod:`.hid_gamepad`). The most recently active device
drives the sticks:

* a gamepad becomes active when a button is newly pressed (triggers included), a stick leaves the
  deadzone, or a stick outside the deadzone moves well away (``motion_threshold``) from where it was
  when that pad was last in use;
* the keyboard becomes active when a stick key (WASD, arrows, IJKL) is newly pressed;
* when the active pad disappears (unplugged, read error, glfw lost it) the keyboard takes over.

Shift/Ctrl (walk/strafe) and Q/E (camera) work whichever device is active. A pad's walk is L1 or
L2 (trigger past ``trigger_threshold``), its strafe R2. Sticks are passed on raw (clamped to the unit
disc): the controllers apply their own deadzone (``Tuning.stick_deadzone``).

Camera azimuth (radians about +Y; growing turns the view left) accumulates from

* the right stick x at ``camera_turn_speed`` rad/s, right = turn right, except while strafing (then
  the right stick aims the character, see :func:`lmm.trajectory.desired_rotation`),
* Q/E at ``keyboard_turn_speed`` rad/s,
* mouse orbit deltas the studio feeds through :meth:`InputManager.add_camera_orbit`.

Nothing here raises into the frame loop.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable

from lmm.controller import InputState

from .glfw_gamepad import GlfwGamepads
from .hid_gamepad import SONY_VENDOR_ID, HIDGamepad
from .keyboard import KeyboardInput
from .state import GamepadState, clamp_unit_disc, radial_deadzone

KEYBOARD_ID = "keyboard"
HID_ID = "hid"
MAX_EVENTS = 200
MAX_DT = 0.25

PAD_WALK_BUTTONS = ("l1", "l2")
PAD_STRAFE_BUTTONS = ("r2",)
#: how Help names a pad button (PlayStation name / Xbox name)
PAD_BUTTON_NAMES = {"l1": "L1/LB", "r1": "R1/RB", "l2": "L2/LT", "r2": "R2/RT"}


def pad_buttons_help() -> str:
    """Help's words for the pad's walk and strafe buttons, from the bindings themselves."""
    def names(buttons):
        return " or ".join(PAD_BUTTON_NAMES.get(b, b.upper()) for b in buttons)
    return f"{names(PAD_WALK_BUTTONS)} walk, {names(PAD_STRAFE_BUTTONS)} strafe"


@dataclass(frozen=True)
class DeviceInfo:
    id: str        # "keyboard", "glfw:<jid>" or "hid"
    name: str      # for the status line
    kind: str      # "keyboard", "glfw" or "hid"
    active: bool


def _wrap_angle(a: float) -> float:
    """Into [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class InputManager:
    """Combines the keyboard, glfw gamepads and a HID pad into one :class:`InputState` per frame.

    ``keyboard``: a :class:`KeyboardInput` the studio feeds (one is made if None).
    ``glfw_module`` / ``hid_module``: ``"auto"`` imports ``glfw`` / ``hid``; pass a stand-in for tests,
    or None to leave that backend out.
    """

    def __init__(self, keyboard: KeyboardInput | None = None, glfw_module="auto", hid_module="auto", *,
                 deadzone: float = 0.2, motion_threshold: float = 0.3, trigger_threshold: float = 0.5,
                 camera_turn_speed: float = 2.0, keyboard_turn_speed: float = 2.0,
                 orbit_while_strafing: bool = False, camera_azimuth: float = 0.0,
                 glfw_init: bool = True, glfw_poll_events: bool = True,
                 hid_rescan_interval: float = 1.0, hid_stale_timeout: float = 1.0,
                 hid_background_scan: bool | None = None,
                 dedupe_sony_pads: bool = True, clock: Callable[[], float] = time.monotonic):
        self.keyboard = keyboard if keyboard is not None else KeyboardInput()
        self.deadzone = float(deadzone)
        self.motion_threshold = float(motion_threshold)
        self.trigger_threshold = float(trigger_threshold)
        self.camera_turn_speed = float(camera_turn_speed)
        self.keyboard_turn_speed = float(keyboard_turn_speed)
        self.orbit_while_strafing = bool(orbit_while_strafing)
        self.dedupe_sony_pads = bool(dedupe_sony_pads)
        self._azimuth = _wrap_angle(float(camera_azimuth))
        self._pending_orbit = 0.0
        self._events: list[str] = []

        self.glfw: GlfwGamepads | None = None
        self.hid: HIDGamepad | None = None
        if glfw_module is not None:
            try:
                self.glfw = GlfwGamepads(glfw_module, init=glfw_init, poll_events=glfw_poll_events)
            except Exception as e:
                self._event(f"glfw gamepads unavailable: {e}")
            else:
                if not self.glfw.available:
                    self._event(f"glfw gamepads unavailable: {self.glfw.error}")
        if hid_module is not None:
            try:
                self.hid = HIDGamepad(hid_module, rescan_interval=hid_rescan_interval,
                                      stale_timeout=hid_stale_timeout, clock=clock,
                                      background_scan=hid_background_scan)
            except Exception as e:
                self._event(f"HID gamepads unavailable: {e}")

        self._seq = 0
        self._last_activity: dict[str, int] = {KEYBOARD_ID: 0}
        self._kb_seen = self.keyboard.activity_count
        self._active = KEYBOARD_ID
        self._pads: dict[str, tuple[str, str, GamepadState]] = {}   # id -> (name, kind, state)
        self._prev: dict[str, GamepadState] = {}
        self._anchor: dict[str, tuple[tuple[float, float], tuple[float, float]]] = {}
        self.last_state = InputState(camera_azimuth=self._azimuth)

    # ---- feeding from the studio --------------------------------------------------------------
    def add_camera_orbit(self, d_azimuth: float) -> None:
        """Add a camera turn in radians (mouse orbit); applied on the next poll. Positive turns left."""
        try:
            d = float(d_azimuth)
        except (TypeError, ValueError):
            return
        if math.isfinite(d):
            self._pending_orbit += d

    @property
    def camera_azimuth(self) -> float:
        return self._azimuth

    @camera_azimuth.setter
    def camera_azimuth(self, value: float) -> None:
        v = float(value)
        if math.isfinite(v):
            self._azimuth = _wrap_angle(v)

    # ---- status -------------------------------------------------------------------------------
    @property
    def active_device_id(self) -> str:
        return self._active

    @property
    def active_device(self) -> str:
        """Display name of the device driving the sticks."""
        if self._active in self._pads:
            return self._pads[self._active][0]
        return self.keyboard.name

    @property
    def devices(self) -> list[DeviceInfo]:
        """Connected devices, keyboard first."""
        out = [DeviceInfo(KEYBOARD_ID, self.keyboard.name, "keyboard", self._active == KEYBOARD_ID)]
        def order(item):
            pid, (_, kind, _) = item
            return kind, int(pid.split(":")[1]) if ":" in pid else 0
        for pid, (name, kind, _) in sorted(self._pads.items(), key=order):
            out.append(DeviceInfo(pid, name, kind, self._active == pid))
        return out

    @property
    def gamepad_states(self) -> dict[str, GamepadState]:
        """Latest reading of each connected pad, by device id (for a debug panel)."""
        return {pid: st for pid, (_, _, st) in self._pads.items()}

    def status_line(self) -> str:
        names = ", ".join(d.name for d in self.devices)
        return f"Input: {self.active_device} | devices: {names}"

    def pop_events(self) -> list[str]:
        """Connection / switch messages since the last call ('connected: ...', 'active: ...')."""
        ev, self._events = self._events, []
        return ev

    def _event(self, msg: str) -> None:
        self._events.append(msg)
        if len(self._events) > MAX_EVENTS:
            del self._events[:-MAX_EVENTS]

    # ---- per frame ----------------------------------------------------------------------------
    def poll(self, dt: float) -> InputState:
        """Read every device and return this frame's input (a new object each call). Never raises."""
        try:
            dt = float(dt)
        except (TypeError, ValueError):
            dt = 0.0
        dt = min(max(dt, 0.0), MAX_DT) if math.isfinite(dt) else 0.0
        try:
            state = self._poll(dt)
        except Exception as e:   # a bug or a backend surprise: fall back to the keyboard this frame
            self._event(f"input error: {e!r}")
            self._pads.clear()
            self._set_active(KEYBOARD_ID)
            state = self._compose(dt, None)
        self.last_state = state
        return state

    def _read_pads(self) -> dict[str, tuple[str, str, GamepadState]]:
        pads: dict[str, tuple[str, str, GamepadState]] = {}
        hid_product = None
        if self.hid is not None:
            try:
                st = self.hid.poll()
                if st is not None:
                    hid_product = self.hid.product_id
                    pads[HID_ID] = (self.hid.name, "hid", st)
            except Exception as e:
                self._event(f"HID poll error: {e!r}")
            self._drain(self.hid)
        if self.glfw is not None:
            try:
                states = self.glfw.poll()
                for jid, st in states.items():
                    pad = self.glfw.pads.get(jid)
                    if pad is None:
                        continue
                    if (self.dedupe_sony_pads and hid_product is not None
                            and pad.vendor_product == (SONY_VENDOR_ID, hid_product)):
                        continue   # the same pad as the HID one: keep one entry
                    pads[f"glfw:{jid}"] = (pad.name, "glfw", st)
            except Exception as e:
                self._event(f"glfw poll error: {e!r}")
            self._drain(self.glfw)
        return pads

    def _drain(self, backend) -> None:
        ev = getattr(backend, "events", None)
        if ev:
            for msg in ev:
                self._event(msg)
            ev.clear()

    def _pad_activity(self, pid: str, st: GamepadState) -> bool:
        prev = self._prev.get(pid)
        if st.buttons - (prev.buttons if prev is not None else frozenset()):
            return True
        sticks = (clamp_unit_disc(st.left_x, st.left_y), clamp_unit_disc(st.right_x, st.right_y))
        prev_sticks = ((prev.left_x, prev.left_y), (prev.right_x, prev.right_y)) if prev is not None else None
        anchor = self._anchor.get(pid)
        for i, (x, y) in enumerate(sticks):
            if math.hypot(x, y) <= self.deadzone:
                continue
            if prev_sticks is None or math.hypot(*clamp_unit_disc(*prev_sticks[i])) <= self.deadzone:
                return True     # left the deadzone
            if anchor is not None and math.hypot(x - anchor[i][0], y - anchor[i][1]) > self.motion_threshold:
                return True     # moved well away from where it rested while another device was in use
        return False

    def _set_active(self, device_id: str) -> None:
        if device_id != self._active:
            self._active = device_id
            self._event(f"active: {self.active_device}")

    def _poll(self, dt: float) -> InputState:
        pads = self._read_pads()
        # forget pads that went away; fall back to the keyboard if it was the active one
        for pid in [p for p in self._pads if p not in pads]:
            self._prev.pop(pid, None)
            self._anchor.pop(pid, None)
            self._last_activity.pop(pid, None)
        lost_active = self._active != KEYBOARD_ID and self._active not in pads
        self._pads = pads
        if lost_active:
            self._seq += 1
            self._last_activity[KEYBOARD_ID] = self._seq
            self._set_active(KEYBOARD_ID)

        active_now = set()
        for pid, (_, _, st) in pads.items():
            if self._pad_activity(pid, st):
                self._seq += 1
                self._last_activity[pid] = self._seq
                active_now.add(pid)
            self._prev[pid] = st
        if self.keyboard.activity_count != self._kb_seen:
            self._kb_seen = self.keyboard.activity_count
            self._seq += 1
            self._last_activity[KEYBOARD_ID] = self._seq

        best = max(self._last_activity, key=lambda k: self._last_activity[k])
        self._set_active(best if best == KEYBOARD_ID or best in pads else KEYBOARD_ID)
        # the anchor (where a stick was when its pad was last in use) follows the active pad and any
        # pad that just showed activity; other pads keep theirs
        for pid, (_, _, st) in pads.items():
            if pid == self._active or pid in active_now or pid not in self._anchor:
                self._anchor[pid] = (clamp_unit_disc(st.left_x, st.left_y), clamp_unit_disc(st.right_x, st.right_y))
        return self._compose(dt, pads.get(self._active, (None, None, None))[2])

    def _pad_binding(self, st: GamepadState, button: str) -> bool:
        if button == "l2":
            return st.left_trigger > self.trigger_threshold
        if button == "r2":
            return st.right_trigger > self.trigger_threshold
        return st.pressed(button)

    def _compose(self, dt: float, pad: GamepadState | None) -> InputState:
        kb = self.keyboard
        if pad is None:
            (lx, ly), (rx, ry) = kb.left_stick(), kb.right_stick()
            walk, strafe = kb.walk, kb.strafe
        else:
            (lx, ly), (rx, ry) = clamp_unit_disc(pad.left_x, pad.left_y), clamp_unit_disc(pad.right_x, pad.right_y)
            walk = kb.walk or any(self._pad_binding(pad, b) for b in PAD_WALK_BUTTONS)
            strafe = kb.strafe or any(self._pad_binding(pad, b) for b in PAD_STRAFE_BUTTONS)

        turn = kb.camera_turn() * self.keyboard_turn_speed * dt
        if not strafe or self.orbit_while_strafing:
            turn -= radial_deadzone(rx, ry, self.deadzone)[0] * self.camera_turn_speed * dt
        turn += self._pending_orbit
        self._pending_orbit = 0.0
        self._azimuth = _wrap_angle(self._azimuth + turn)
        return InputState(left_x=float(lx), left_y=float(ly), right_x=float(rx), right_y=float(ry),
                          walk=bool(walk), strafe=bool(strafe), camera_azimuth=self._azimuth)

    def close(self) -> None:
        """Release the HID device and forget the pads (glfw itself is left initialised)."""
        for backend in (self.hid, self.glfw):
            if backend is not None:
                try:
                    backend.close()
                except Exception:
                    pass
        self._pads.clear()
        self._set_active(KEYBOARD_ID)
