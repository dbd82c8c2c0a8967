"""The studio's input layer (app/input): keyboard mapping, DualShock 4 / DualSense USB report parsing,
the hidapi and glfw pollers with fake backends (plug, unplug, replug), the manager's device switching
and camera, and the real glfw/hid modules with no pads attached."""
from __future__ import annotations

import json
import math
import subprocess
import sys
import textwrap
import warnings
from collections import deque, namedtuple
from pathlib import Path

import pytest

from app.input import (KEY_BINDINGS, GamepadState, GlfwGamepads, HIDGamepad, HIDReportError, InputManager,
                       KeyboardInput, build_key_lookup, parse_ds4_usb_report, parse_dualsense_usb_report,
                       state_from_glfw)
from app.input.glfw_gamepad import guid_vendor_product
from app.input.keyboard import ACTION_KEYS, DEARPYGUI_KEYS
from app.input.state import radial_deadzone
from lmm.controller import InputState

REPO = Path(__file__).resolve().parents[3]
DT = 1.0 / 60.0


def report(*rows: str) -> bytes:
    data = bytes.fromhex(" ".join(rows))
    assert len(data) == 64
    return data


# ---- recorded reports (USB input report 0x01, 64 bytes) -------------------------------------------------
# DualShock 4: 1-4 sticks, 5 hat + face buttons, 6 shoulders/share/options/L3/R3, 7 PS/touchpad/counter,
# 8-9 L2/R2, then timestamp, temperature, gyro, accelerometer, battery and touch data.
DS4_TAIL = ("00 01 00 9a 00 40 20 c4 05 00 00 00 00 00 1b 00",
            "00 01 80 00 00 00 80 00 00 00 00 80 00 00 00 80",
            "00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00")
DS4_NEUTRAL = report("01 80 80 80 80 08 00 00 00 00 a5 3c 1b fe ff 02", *DS4_TAIL)
DS4_RESTING = report("01 7e 81 82 7f 08 00 04 00 00 b1 3c 1b fe ff 02", *DS4_TAIL)   # off-centre sticks
# left stick up-left, right stick right, cross, dpad right, L1 + L2 (full), PS, counter 2
DS4_LEFT_UP_CROSS = report("01 00 00 ff 80 22 05 09 ff 00 b0 3d 1b fe ff 02", *DS4_TAIL)
# face buttons, R1 R2 share options L3 R3, touchpad click, R2 half way
DS4_BUTTONS = report("01 40 c0 80 00 f8 fa 06 00 80 c2 3e 1b fe ff 02", *DS4_TAIL)

# DualSense: 1-4 sticks, 5-6 L2/R2, 7 counter, 8 hat + face, 9 shoulders/create/options/L3/R3, 10 PS/pad/mute
DS_TAIL = ("02 00 fd ff 03 00 15 00 e4 1f 4c 07 d3 8a 44 00",
           "00 80 00 00 00 80 00 00 00 00 09 09 00 00 00 00",
           "00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00")
DS_NEUTRAL = report("01 80 80 80 80 00 00 2a 08 00 00 00 c6 2b 9e 01", *DS_TAIL)
DS_RESTING = report("01 7f 80 80 7f 00 00 2b 08 00 00 00 c6 2b 9e 01", *DS_TAIL)
# left stick right, right stick down-left, L2 at 0x33, R2 full, triangle, dpad left, R1 + R2, PS, mute
DS_RIGHT_TRIANGLE = report("01 ff 80 00 ff 33 ff 2c 86 0a 05 00 c6 2b 9e 01", *DS_TAIL)
# dpad up-right, square cross circle, L1 L2 create options L3 R3, touchpad, L2 full
DS_BUTTONS = report("01 40 c0 c0 40 ff 00 2d 71 f5 02 00 c6 2b 9e 01", *DS_TAIL)


# ---- report parsing -----------------------------------------------------------------------------------
def test_ds4_neutral_and_resting_reports():
    s = parse_ds4_usb_report(DS4_NEUTRAL)
    assert s == GamepadState(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, frozenset(), 8)
    r = parse_ds4_usb_report(DS4_RESTING)   # counter bits in byte 7 are not the PS button
    assert (r.left_x, r.left_y, r.right_x, r.right_y) == (-2 / 128, -1 / 127, 2 / 127, 1 / 128)
    assert r.buttons == frozenset() and r.hat == 8 and r.dpad == (0, 0)


def test_ds4_sticks_triggers_buttons():
    s = parse_ds4_usb_report(DS4_LEFT_UP_CROSS)
    assert (s.left_x, s.left_y, s.right_x, s.right_y) == (-1.0, 1.0, 1.0, 0.0)
    assert (s.left_trigger, s.right_trigger) == (1.0, 0.0)
    assert s.buttons == {"south", "dpad_right", "l1", "l2", "home"}
    assert s.hat == 2 and s.dpad == (1, 0)
    assert s.pressed("cross") and s.pressed("PS") and s.pressed("L1") and s.pressed("a")
    assert not s.pressed("circle") and not s.pressed("options")

    b = parse_ds4_usb_report(DS4_BUTTONS)
    assert (b.left_x, b.left_y, b.right_x, b.right_y) == (-0.5, -64 / 127, 0.0, 1.0)
    assert (b.left_trigger, b.right_trigger) == (0.0, 128 / 255)
    assert b.buttons == {"west", "south", "east", "north", "r1", "r2", "select", "start", "l3", "r3", "touchpad"}
    for name in ("square", "cross", "circle", "triangle", "R1", "R2", "share", "options", "L3", "R3"):
        assert b.pressed(name), name
    assert b.hat == 8 and not b.pressed("home")


def test_dualsense_reports():
    assert parse_dualsense_usb_report(DS_NEUTRAL) == GamepadState(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, frozenset(), 8)
    r = parse_dualsense_usb_report(DS_RESTING)
    assert (r.left_x, r.left_y, r.right_x, r.right_y) == (-1 / 128, 0.0, 0.0, 1 / 128)

    s = parse_dualsense_usb_report(DS_RIGHT_TRIANGLE)
    assert (s.left_x, s.left_y, s.right_x, s.right_y) == (1.0, 0.0, -1.0, -1.0)
    assert (s.left_trigger, s.right_trigger) == (0x33 / 255, 1.0)
    assert s.buttons == {"north", "dpad_left", "r1", "r2", "home", "mute"}
    assert s.hat == 6 and s.dpad == (-1, 0) and s.pressed("triangle") and s.pressed("ps")

    b = parse_dualsense_usb_report(DS_BUTTONS)
    assert (b.left_x, b.left_y, b.right_x, b.right_y) == (-0.5, -64 / 127, 64 / 127, 0.5)
    assert (b.left_trigger, b.right_trigger) == (1.0, 0.0)
    assert b.buttons == {"dpad_up", "dpad_right", "west", "south", "east", "l1", "l2", "select", "start",
                         "l3", "r3", "touchpad"}
    assert b.hat == 1 and b.dpad == (1, 1) and b.pressed("create") and b.pressed("options")


def test_hidapi_list_of_ints_parses_like_bytes():
    assert parse_ds4_usb_report(list(DS4_BUTTONS)) == parse_ds4_usb_report(DS4_BUTTONS)
    assert parse_dualsense_usb_report(bytearray(DS_BUTTONS)) == parse_dualsense_usb_report(DS_BUTTONS)
    # the parsers read only the leading bytes they need
    assert parse_ds4_usb_report(DS4_BUTTONS[:10]) == parse_ds4_usb_report(DS4_BUTTONS)
    assert parse_dualsense_usb_report(DS_BUTTONS[:11]) == parse_dualsense_usb_report(DS_BUTTONS)


MALFORMED = [
    b"", b"\x01", None, DS4_NEUTRAL[:9],                               # empty / too short
    b"\x11" + DS4_NEUTRAL[1:], b"\x31" + DS_NEUTRAL[1:], b"\x00" * 64,  # wrong report ids (Bluetooth, none)
    [1, 300, 0, 0, 0, 0, 0, 0, 0, 0, 0], "0180808080", 12345, [None] * 64,
]
CASES = ([(parse_ds4_usb_report, d) for d in MALFORMED]
         + [(parse_dualsense_usb_report, d) for d in MALFORMED + [DS_NEUTRAL[:10]]])   # DualSense BT simple report


@pytest.mark.parametrize("parse,data", CASES, ids=[f"{p.__name__[6:10]}-{i}" for i, (p, _) in enumerate(CASES)])
def test_malformed_reports_give_none_or_report_error(parse, data):
    assert parse(data) is None
    with pytest.raises(HIDReportError):
        parse(data, strict=True)


# ---- fake backends --------------------------------------------------------------------------------------
class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t

    def tick(self, dt=DT):
        self.t += dt


class FakeHidDevice:
    def __init__(self, hub):
        self.hub, self.path, self.closed, self.nonblocking = hub, None, False, False

    def open_path(self, path):
        pad = self.hub.pads.get(path)
        if pad is None or not pad["present"]:
            raise OSError("open failed")
        if pad.get("deny"):
            raise OSError("open failed: permission denied")
        self.path = path
        self.hub.opened.append(path)

    def set_nonblocking(self, v):
        self.nonblocking = bool(v)

    def read(self, n):
        assert self.nonblocking, "reads must be non-blocking"
        if self.closed:
            raise ValueError("not open")
        pad = self.hub.pads.get(self.path)
        if pad is None or not pad["present"]:
            if pad is not None and pad.get("silent_unplug"):
                return []
            raise OSError("read error")
        if pad["queue"]:
            pad["last"] = pad["queue"].popleft()
            return list(pad["last"][:n])
        if pad["streaming"] and pad["last"] is not None and pad["last_t"] != self.hub.clock():
            pad["last_t"] = self.hub.clock()   # a real pad keeps reporting (~250 Hz): one repeat per tick
            return list(pad["last"][:n])
        return []

    def close(self):
        self.closed = True


class FakeHid:
    """Stands in for the ``hid`` module: pads can be plugged, fed reports, and unplugged."""

    def __init__(self, clock):
        self.clock, self.pads, self.enumerate_calls, self.opened = clock, {}, 0, []
        self.enumerate_error = None

    def plug(self, path, product_id, first_report, streaming=True):
        self.pads[path] = dict(product_id=product_id, present=True, queue=deque([first_report]), last=None,
                               last_t=None, streaming=streaming)

    def feed(self, path, data):
        self.pads[path]["queue"].append(data)

    def unplug(self, path, silent=False):
        self.pads[path].update(present=False, silent_unplug=silent, queue=deque(), last=None)

    def replug(self, path, first_report):
        self.pads[path].update(present=True, silent_unplug=False, queue=deque([first_report]))

    def enumerate(self, vendor_id=0, product_id=0):
        self.enumerate_calls += 1
        if self.enumerate_error:
            raise self.enumerate_error
        return [dict(path=p, vendor_id=0x054C, product_id=d["product_id"], product_string="Wireless Controller",
                     interface_number=3, bus_type=1)
                for p, d in self.pads.items() if d["present"] and vendor_id in (0, 0x054C)]

    def device(self):
        return FakeHidDevice(self)


GState = namedtuple("GLFWgamepadstate", "buttons axes")
BTN = {"a": 0, "b": 1, "x": 2, "y": 3, "lb": 4, "rb": 5, "back": 6, "start": 7, "guide": 8, "ls": 9, "rs": 10,
       "up": 11, "right": 12, "down": 13, "left": 14}


def glfw_raw(lx=0.0, ly=0.0, rx=0.0, ry=0.0, lt=-1.0, rt=-1.0, pressed=()):
    buttons = [0] * 15
    for b in pressed:
        buttons[BTN[b]] = 1
    return GState(buttons, [lx, ly, rx, ry, lt, rt])


class FakeGlfw:
    """Stands in for pyGLFW: joysticks come and go; glfw's y axes point down, triggers rest at -1."""

    class GLFWError(UserWarning):
        pass

    def __init__(self, init_ok=True):
        self.init_ok, self.joysticks, self.init_calls, self.poll_events_calls = init_ok, {}, 0, 0

    def connect(self, jid, name, guid="", raw=None, gamepad=True):
        self.joysticks[jid] = dict(name=name, guid=guid, raw=raw or glfw_raw(), gamepad=gamepad)

    def init(self):
        self.init_calls += 1
        if not self.init_ok:
            warnings.warn("(65550) b'X11: The DISPLAY environment variable is missing'", self.GLFWError)
        return self.init_ok

    def poll_events(self):
        self.poll_events_calls += 1

    def joystick_present(self, jid):
        return int(jid in self.joysticks)

    def joystick_is_gamepad(self, jid):
        return int(jid in self.joysticks and self.joysticks[jid]["gamepad"])

    def get_gamepad_state(self, jid):
        j = self.joysticks.get(jid)
        if j is None or not j["gamepad"]:
            return None
        if isinstance(j["raw"], Exception):
            raise j["raw"]
        return j["raw"]

    def get_gamepad_name(self, jid):
        return self.joysticks[jid]["name"]

    def get_joystick_guid(self, jid):
        return self.joysticks[jid]["guid"]


# ---- keyboard -------------------------------------------------------------------------------------------
def test_keyboard_sticks_diagonals_and_release():
    kb = KeyboardInput()
    assert kb.left_stick() == (0.0, 0.0) and kb.right_stick() == (0.0, 0.0)
    kb.press("w")
    assert kb.left_stick() == (0.0, 1.0)
    kb.press("d")
    x, y = kb.left_stick()
    assert math.isclose(x, math.sqrt(0.5)) and math.isclose(y, math.sqrt(0.5)) and math.isclose(math.hypot(x, y), 1.0)
    kb.press("a")   # left and right cancel
    assert kb.left_stick() == (0.0, 1.0)
    kb.release("w"), kb.release("a"), kb.release("d")
    assert kb.left_stick() == (0.0, 0.0)
    kb.press("Down"), kb.press("ArrowLeft")
    x, y = kb.left_stick()
    assert math.isclose(x, -math.sqrt(0.5)) and math.isclose(y, -math.sqrt(0.5))
    kb.press("s")   # arrow + its WASD twin is still one unit
    assert math.isclose(math.hypot(*kb.left_stick()), 1.0)
    kb.release_all()
    assert kb.left_stick() == (0.0, 0.0) and kb.held == frozenset()
    kb.set_keys(["i", "l"])
    x, y = kb.right_stick()
    assert math.isclose(x, math.sqrt(0.5)) and math.isclose(y, math.sqrt(0.5))
    kb.set_keys([])
    assert kb.right_stick() == (0.0, 0.0)


def test_keyboard_walk_strafe_camera_and_aliases():
    kb = KeyboardInput()
    assert not kb.walk and not kb.strafe and kb.camera_turn() == 0.0
    kb.press("LShift")
    kb.press("right_control")
    assert kb.walk and kb.strafe
    kb.release("shift")
    kb.release("ctrl")
    assert not kb.walk and not kb.strafe
    kb.press("q")
    assert kb.camera_turn() == 1.0
    kb.press("e")
    assert kb.camera_turn() == 0.0
    kb.release("q")
    assert kb.camera_turn() == -1.0
    kb.press("mvKey_W")
    assert kb.is_down("w") and kb.left_stick() == (0.0, 1.0)
    kb.enabled = False   # e.g. a text field has focus
    assert kb.left_stick() == (0.0, 0.0) and kb.camera_turn() == 0.0 and not kb.walk


def test_keyboard_activity_counts_only_stick_keys():
    kb = KeyboardInput()
    kb.press("shift"), kb.press("ctrl"), kb.press("q"), kb.press("f5")
    assert kb.activity_count == 0
    kb.press("w")
    kb.press("w")   # auto-repeat is not a new press
    assert kb.activity_count == 1
    kb.set_keys(["w", "shift"])
    assert kb.activity_count == 1
    kb.set_keys(["w", "left"])
    assert kb.activity_count == 2


def test_key_bindings_table_and_dearpygui_lookup():
    assert {a for _, a, _ in KEY_BINDINGS} >= set(ACTION_KEYS)
    for keys in ACTION_KEYS.values():
        for k in keys:
            assert k in DEARPYGUI_KEYS
    fake_dpg = {"mvKey_W": 568, "mvKey_LShift": 528, "mvKey_RShift": 529, "mvKey_Up": 515}
    lookup = build_key_lookup(fake_dpg.get)
    assert lookup == {568: "w", 528: "shift", 529: "shift", 515: "up"}


# ---- glfw gamepads --------------------------------------------------------------------------------------
def test_glfw_state_conversion():
    s = state_from_glfw(glfw_raw(lx=0.5, ly=-1.0, rx=-0.25, ry=0.75, lt=1.0, rt=0.0, pressed=("a", "lb", "up", "left")))
    assert (s.left_x, s.left_y, s.right_x, s.right_y) == (0.5, 1.0, -0.25, -0.75)
    assert (s.left_trigger, s.right_trigger) == (1.0, 0.5)
    assert s.buttons == {"south", "l1", "dpad_up", "dpad_left", "l2"}   # r2 needs more than half travel
    assert s.hat == 7 and s.pressed("cross") and s.pressed("A")
    assert state_from_glfw(glfw_raw()) == GamepadState()
    assert state_from_glfw(GState([0] * 3, [0.0] * 6)) is None
    assert state_from_glfw(object()) is None


def test_xbox_playstation_switch_pads_read_alike():
    g = FakeGlfw()
    raw = glfw_raw(lx=0.3, ly=-0.6, pressed=("b", "rb"))
    for jid, name in enumerate(("Xbox Controller", "PS5 Controller", "Nintendo Switch Pro Controller")):
        g.connect(jid, name, raw=raw)
    pads = GlfwGamepads(g)
    states = pads.poll()
    assert sorted(states) == [0, 1, 2] and len(set(states.values())) == 1
    assert [p.name for p in pads.pads.values()] == ["Xbox Controller (glfw #0)", "PS5 Controller (glfw #1)",
                                                    "Nintendo Switch Pro Controller (glfw #2)"]
    assert g.poll_events_calls == 1


def test_glfw_init_failure_is_handled_quietly():
    g = FakeGlfw(init_ok=False)
    g.connect(0, "Xbox Controller")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pads = GlfwGamepads(g)
        assert pads.poll() == {}
        m = InputManager(glfw_module=g, hid_module=None)
        m.keyboard.press("w")
        assert m.poll(DT).left_y == 1.0
    assert not [w for w in caught if issubclass(w.category, FakeGlfw.GLFWError)]
    assert not pads.available and "DISPLAY" in pads.error
    assert any("glfw gamepads unavailable" in e for e in m.pop_events())


def test_glfw_joystick_disappears_mid_run_and_errors_do_not_escape():
    clock = FakeClock()
    g = FakeGlfw()
    g.connect(0, "Xbox Controller", guid="030000005e0400008e02000014010000")
    g.connect(1, "Some Joystick", gamepad=False)   # no mapping: ignored
    m = InputManager(glfw_module=g, hid_module=None, clock=clock)
    m.poll(DT)
    assert [d.name for d in m.devices] == ["Keyboard", "Xbox Controller (glfw #0)"] and m.active_device == "Keyboard"

    g.joysticks[0]["raw"] = glfw_raw(lx=0.8, ly=-0.6)
    s = m.poll(DT)
    assert m.active_device == "Xbox Controller (glfw #0)" and (s.left_x, s.left_y) == pytest.approx((0.8, 0.6))

    del g.joysticks[0]   # unplugged
    m.keyboard.press("s")
    s = m.poll(DT)
    assert m.active_device == "Keyboard" and (s.left_x, s.left_y) == (0.0, -1.0)
    assert [d.kind for d in m.devices] == ["keyboard"]
    events = m.pop_events()
    assert "disconnected: Xbox Controller (glfw #0)" in events and "active: Keyboard" in events

    g.connect(0, "Xbox Controller", raw=RuntimeError("driver hiccup"))   # back, but reading it fails
    m.poll(DT)
    assert [d.kind for d in m.devices] == ["keyboard"]
    g.joysticks[0]["raw"] = glfw_raw(pressed=("a",))
    m.poll(DT)
    assert m.active_device == "Xbox Controller (glfw #0)"

    def boom(jid):
        raise g.GLFWError("(65544) joystick went away")   # pyGLFW with ERROR_REPORTING = 'raise'
    g.joystick_present = boom
    m.keyboard.release("s")
    s = m.poll(DT)
    assert m.active_device == "Keyboard" and s == InputState(camera_azimuth=s.camera_azimuth)


# ---- HID pads -------------------------------------------------------------------------------------------
def test_hid_unplug_falls_back_to_keyboard_and_replug_resumes():
    clock = FakeClock()
    hub = FakeHid(clock)
    path = b"/dev/hidraw3"
    hub.plug(path, 0x09CC, DS4_NEUTRAL)
    m = InputManager(glfw_module=None, hid_module=hub, clock=clock)
    m.keyboard.press("w")
    s = m.poll(DT)   # pad found and opened; its neutral report is no activity
    assert [d.name for d in m.devices] == ["Keyboard", "DualShock 4 (v2) (USB HID)"]
    assert m.active_device == "Keyboard" and s.left_y == 1.0
    m.keyboard.release("w")

    hub.feed(path, DS4_LEFT_UP_CROSS)
    clock.tick()
    s = m.poll(DT)
    assert m.active_device_id == "hid"
    r = math.sqrt(0.5)                    # the raw corner (-1, 1) is clamped onto the unit disc
    assert (s.left_x, s.left_y, s.right_x, s.right_y) == pytest.approx((-r, r, 1.0, 0.0))
    assert s.walk and not s.strafe        # L1 / L2
    clock.tick()
    assert m.poll(DT).left_x == pytest.approx(-r)     # the pad keeps reporting the same state

    hub.unplug(path)
    m.keyboard.press("a")
    clock.tick()
    n_enum = hub.enumerate_calls
    s = m.poll(DT)                        # read raises OSError: no exception, keyboard again
    assert m.active_device == "Keyboard" and (s.left_x, s.left_y) == (-1.0, 0.0)
    assert [d.kind for d in m.devices] == ["keyboard"]
    assert any(e.startswith("disconnected: DualShock 4") for e in m.pop_events())

    for _ in range(30):                   # half a second: no new enumerate
        clock.tick()
        m.poll(DT)
    assert hub.enumerate_calls == n_enum
    clock.t += 0.6
    m.poll(DT)                             # >= 1 s after the unplug: one look, still nothing
    assert hub.enumerate_calls == n_enum + 1 and not m.hid.connected

    hub.replug(path, DS4_NEUTRAL)
    clock.tick(0.5)
    m.poll(DT)
    assert not m.hid.connected             # next look is due 1 s after the last one
    clock.tick(0.5)
    m.poll(DT)
    assert m.hid.connected and hub.enumerate_calls == n_enum + 2
    assert m.active_device == "Keyboard"   # plugging in is not activity
    hub.feed(path, DS4_BUTTONS)
    clock.tick()
    s = m.poll(DT)
    assert m.active_device_id == "hid" and s.strafe and (s.left_x, s.right_y) == (-0.5, 1.0)


def test_hid_survives_enumerate_open_and_nonblocking_failures():
    clock = FakeClock()
    hub = FakeHid(clock)
    hub.enumerate_error = OSError("hid_enumerate failed")
    pad = HIDGamepad(hub, clock=clock)
    assert pad.poll() is None and not pad.connected
    hub.enumerate_error = None
    hub.plug(b"p1", 0x0CE6, DS_NEUTRAL)
    hub.pads[b"p1"]["deny"] = True          # no permission on /dev/hidraw*
    clock.tick(1.0)
    assert pad.poll() is None and "permission" in pad.last_error
    hub.pads[b"p1"]["deny"] = False
    clock.tick(1.0)
    assert pad.poll() == parse_dualsense_usb_report(DS_NEUTRAL) and pad.name == "DualSense (USB HID)"

    class NoNonblocking(FakeHidDevice):
        def set_nonblocking(self, v):
            raise OSError("cannot set non-blocking")
    pad2 = HIDGamepad(hub, clock=clock)
    hub.device = lambda: NoNonblocking(hub)
    assert pad2.poll() is None and not pad2.connected   # never used in blocking mode

    class Broken:
        def enumerate(self, **kw):
            return [{"path": b"x", "vendor_id": 0x054C, "product_id": 0x05C4}, "junk", {"product_id": "nan"}]

        def device(self):
            raise RuntimeError("unexpected")
    pad3 = HIDGamepad(Broken(), clock=clock)
    assert pad3.poll() is None and not pad3.connected


def test_hid_background_scan_opens_on_a_later_poll():
    clock = FakeClock()
    hub = FakeHid(clock)
    hub.plug(b"p", 0x0DF2, DS_BUTTONS)
    pad = HIDGamepad(hub, clock=clock, background_scan=True)
    assert pad.poll() is None                 # the scan runs off the frame thread
    assert pad._scan_job.wait(5.0)
    assert pad.poll() == parse_dualsense_usb_report(DS_BUTTONS) and pad.name == "DualSense Edge (USB HID)"
    hub.unplug(b"p")
    clock.tick()
    assert pad.poll() is None and not pad.connected
    hub.enumerate_error = OSError("boom")
    clock.tick(1.0)
    assert pad.poll() is None
    assert pad._scan_job.wait(5.0)
    assert pad.poll() is None and "boom" in pad.last_error


def test_hid_ignores_unknown_pads_and_bluetooth_and_bad_reports():
    clock = FakeClock()
    hub = FakeHid(clock)
    hub.plug(b"other", 0x0268, DS4_NEUTRAL)   # a PlayStation 3 pad: not handled here
    pad = HIDGamepad(hub, clock=clock)
    assert pad.poll() is None and not pad.connected
    bt = dict(path=b"bt", vendor_id=0x054C, product_id=0x0CE6, bus_type=2)
    hub.enumerate = lambda vendor_id=0, product_id=0: [bt]
    clock.tick(1.0)
    assert pad.poll() is None and not pad.connected

    hub2 = FakeHid(clock)
    hub2.plug(b"ds", 0x0CE6, DS_NEUTRAL, streaming=False)
    pad = HIDGamepad(hub2, clock=clock)
    assert pad.poll() == GamepadState()
    hub2.feed(b"ds", b"\x31" + DS_NEUTRAL[1:])   # a Bluetooth-format report
    hub2.feed(b"ds", b"\x01\x80")
    hub2.feed(b"ds", DS_RIGHT_TRIANGLE)
    hub2.feed(b"ds", b"")
    assert pad.poll() == parse_dualsense_usb_report(DS_RIGHT_TRIANGLE) and pad.bad_reports == 2


def test_hid_silent_unplug_is_noticed_and_stale_state_dropped():
    clock = FakeClock()
    hub = FakeHid(clock)
    hub.plug(b"p", 0x05C4, DS4_LEFT_UP_CROSS)
    m = InputManager(glfw_module=None, hid_module=hub, clock=clock)
    m.poll(DT)
    assert m.active_device_id == "hid"
    hub.unplug(b"p", silent=True)        # reads just return nothing, the path vanishes from enumerate
    for _ in range(30):
        clock.tick()
        assert m.poll(DT).left_x < -0.7   # the last reading holds briefly
    clock.tick(0.6)
    s = m.poll(DT)
    assert m.active_device == "Keyboard" and s.left_x == 0.0 and not m.hid.connected


def test_same_sony_pad_seen_by_glfw_and_hid_is_listed_once():
    clock = FakeClock()
    hub = FakeHid(clock)
    hub.plug(b"p", 0x09CC, DS4_NEUTRAL)
    g = FakeGlfw()
    g.connect(0, "PS4 Controller", guid="030000004c050000cc09000011810000")
    g.connect(1, "Xbox Controller", guid="030000005e0400008e02000014010000")
    m = InputManager(glfw_module=g, hid_module=hub, clock=clock)
    m.poll(DT)
    assert [d.id for d in m.devices] == ["keyboard", "glfw:1", "hid"]
    assert guid_vendor_product("030000004c050000cc09000011810000") == (0x054C, 0x09CC)
    assert guid_vendor_product(b"030000005e0400008e02000014010000") == (0x045E, 0x028E)
    assert guid_vendor_product("78696e70757401000000000000000000") is None
    assert guid_vendor_product("not a guid") is None and guid_vendor_product(None) is None


# ---- manager: switching and camera ----------------------------------------------------------------------
def _pad_manager():
    clock = FakeClock()
    g = FakeGlfw()
    g.connect(0, "Xbox Controller")
    m = InputManager(glfw_module=g, hid_module=None, clock=clock)
    m.poll(DT)
    return m, g


def test_most_recently_active_device_wins():
    m, g = _pad_manager()
    g.joysticks[0]["raw"] = glfw_raw(lx=0.1, ly=-0.1)   # inside the deadzone: not activity
    m.keyboard.press("d")
    s = m.poll(DT)
    assert m.active_device == "Keyboard" and s.left_x == 1.0
    g.joysticks[0]["raw"] = glfw_raw(lx=0.1, ly=-0.1, pressed=("x",))   # a button press takes over
    s = m.poll(DT)
    assert m.active_device_id == "glfw:0" and (s.left_x, s.left_y) == pytest.approx((0.1, 0.1))
    m.keyboard.press("w")                     # a new stick key: back to the keyboard
    g.joysticks[0]["raw"] = glfw_raw(lx=-0.9, ly=0.0, pressed=("x",))
    s = m.poll(DT)                            # same frame as the pad's stick leaving the deadzone
    assert m.active_device == "Keyboard"
    assert (s.left_x, s.left_y) == pytest.approx((math.sqrt(0.5), math.sqrt(0.5)))
    m.keyboard.release("w"), m.keyboard.release("d")
    m.keyboard.press("shift")                 # modifiers and camera keys do not switch
    m.keyboard.press("q")
    g.joysticks[0]["raw"] = glfw_raw(lx=-0.9, ly=0.05, pressed=("x",))   # held stick, small wobble
    s = m.poll(DT)
    assert m.active_device == "Keyboard" and s.left_x == 0.0 and s.walk
    g.joysticks[0]["raw"] = glfw_raw(lx=0.0, ly=0.95)   # moved well away: the pad again
    s = m.poll(DT)
    assert m.active_device_id == "glfw:0" and s.left_y == pytest.approx(-0.95) and s.walk   # shift still walks


def test_pad_walk_strafe_bindings():
    m, g = _pad_manager()
    g.joysticks[0]["raw"] = glfw_raw(lx=1.0, ly=-1.0)           # a square gate corner: clamped to the disc
    s = m.poll(DT)
    assert math.isclose(math.hypot(s.left_x, s.left_y), 1.0) and not s.walk and not s.strafe
    g.joysticks[0]["raw"] = glfw_raw(lx=1.0, pressed=("lb",))
    assert m.poll(DT).walk
    g.joysticks[0]["raw"] = glfw_raw(lx=1.0, lt=0.5)            # 75 % left trigger
    assert m.poll(DT).walk
    g.joysticks[0]["raw"] = glfw_raw(lx=1.0, rt=-0.2)           # 40 %: not yet
    assert not m.poll(DT).strafe
    g.joysticks[0]["raw"] = glfw_raw(lx=1.0, rt=0.2)
    s = m.poll(DT)
    assert s.strafe and not s.walk


def test_camera_azimuth_from_right_stick_keys_and_mouse():
    m, g = _pad_manager()
    g.joysticks[0]["raw"] = glfw_raw(rx=1.0)                    # right stick right: turn right
    s = m.poll(0.1)
    assert m.active_device_id == "glfw:0" and s.camera_azimuth == pytest.approx(-0.2)
    g.joysticks[0]["raw"] = glfw_raw(rx=0.1)                    # inside the deadzone: no turn
    assert m.poll(0.1).camera_azimuth == pytest.approx(-0.2)
    g.joysticks[0]["raw"] = glfw_raw(rx=-0.6)
    assert m.poll(0.1).camera_azimuth == pytest.approx(-0.2 + 2.0 * 0.1 * radial_deadzone(0.6, 0, 0.2)[0])
    az = m.camera_azimuth
    g.joysticks[0]["raw"] = glfw_raw(rx=1.0, rt=1.0)            # strafing: the right stick aims, no orbit
    s = m.poll(0.1)
    assert s.strafe and s.right_x == 1.0 and s.camera_azimuth == pytest.approx(az)
    m.keyboard.press("q")                                       # Q turns left while strafing too
    assert m.poll(0.25).camera_azimuth == pytest.approx(az + 0.5)
    assert m.poll(0.25).camera_azimuth == pytest.approx(az + 1.0)
    m.keyboard.release("q")
    g.joysticks[0]["raw"] = glfw_raw()
    m.add_camera_orbit(0.25)
    m.add_camera_orbit(0.05)
    m.add_camera_orbit(float("nan"))
    assert m.poll(DT).camera_azimuth == pytest.approx(az + 1.3)
    assert m.poll(DT).camera_azimuth == pytest.approx(az + 1.3)   # orbit deltas apply once
    m.camera_azimuth = 3.1
    m.add_camera_orbit(0.2)
    assert m.poll(DT).camera_azimuth == pytest.approx(3.3 - 2 * math.pi)


def test_keyboard_only_manager_and_odd_dt():
    m = InputManager(glfw_module=None, hid_module=None)
    assert m.poll(DT) == InputState() and m.active_device == "Keyboard"
    assert m.status_line() == "Input: Keyboard | devices: Keyboard"
    m.keyboard.press("j")    # keyboard right stick left: turns the camera left when not strafing
    for dt in (float("nan"), -1.0, None, "x", 10.0):
        s = m.poll(dt)
        assert s.right_x == -1.0
    assert s.camera_azimuth == pytest.approx(2.0 * 0.25)   # a long frame is capped at 0.25 s
    m.keyboard.press("ctrl")
    assert m.poll(1.0).camera_azimuth == pytest.approx(0.5)
    m.close()
    assert m.poll(DT).strafe


def test_backend_exception_falls_back_to_keyboard():
    m, g = _pad_manager()
    g.joysticks[0]["raw"] = glfw_raw(ly=-1.0)
    assert m.poll(DT).left_y == 1.0 and m.active_device_id == "glfw:0"

    def broken():
        raise RuntimeError("bug in a backend")
    m.glfw.poll = broken
    m.keyboard.press("left")
    s = m.poll(DT)
    assert m.active_device == "Keyboard" and s.left_x == -1.0
    assert any("glfw poll error" in e for e in m.pop_events())


# ---- the real modules, no pads attached ----------------------------------------------------------------
def test_real_glfw_and_hid_without_devices(monkeypatch):
    pytest.importorskip("glfw")
    pytest.importorskip("hid")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")       # nothing may leak out as a warning either
        m = InputManager()
        assert m.hid is not None and m.hid.available and m.glfw is not None
        m.keyboard.set_keys(["w", "shift"])
        for _ in range(3):
            s = m.poll(DT)
        assert (s.left_y, s.walk, s.strafe) == (1.0, True, False)
        assert m.active_device == "Keyboard" and [d.kind for d in m.devices] == ["keyboard"]
        m.close()


def _start_xvfb():
    from viewer.xvfb import Xvfb, XvfbUnavailable

    try:
        return Xvfb("320x240x24")
    except XvfbUnavailable as e:
        pytest.skip(str(e))


@pytest.mark.gui
def test_real_glfw_initialises_under_xvfb_and_polls_nothing():
    pytest.importorskip("glfw")
    with _start_xvfb() as server:
        script = textwrap.dedent("""
            import json, warnings
            warnings.simplefilter("error")
            from app.input import InputManager
            m = InputManager()
            m.keyboard.press("a")
            s = m.poll(1 / 60)
            print(json.dumps({"glfw": m.glfw.available, "devices": [d.kind for d in m.devices],
                              "left_x": s.left_x, "active": m.active_device}))
            m.close()
        """)
        out = subprocess.run([sys.executable, "-c", script], env=server.env(PYTHONPATH=str(REPO)), cwd=REPO,
                             capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        res = json.loads(out.stdout.strip().splitlines()[-1])
        assert res == {"glfw": True, "devices": ["keyboard"], "left_x": -1.0, "active": "Keyboard"}
