"""The studio's input layer: keyboard, gamepads through glfw, and DualShock 4 / DualSense through hidapi.

No GUI toolkit is imported here: the studio forwards key names to :class:`KeyboardInput` and
mouse orbit deltas to :meth:`InputManager.add_camera_orbit`, then calls
:meth:`InputManager.poll` once per frame to get a :class:`lmm.controller.InputState`.
"""
from .glfw_gamepad import GlfwGamepads, state_from_glfw
from .hid_gamepad import (KNOWN_PRODUCTS, SONY_VENDOR_ID, HIDGamepad, HIDReportError, parse_dualsense_usb_report,
                          parse_ds4_usb_report)
from .keyboard import DEARPYGUI_KEYS, KEY_BINDINGS, KeyboardInput, build_key_lookup, normalize_key_name
from .manager import DeviceInfo, InputManager
from .state import BUTTONS, GamepadState

__all__ = [
    "BUTTONS", "DEARPYGUI_KEYS", "DeviceInfo", "GamepadState", "GlfwGamepads", "HIDGamepad", "HIDReportError",
    "InputManager", "KEY_BINDINGS", "KNOWN_PRODUCTS", "KeyboardInput", "SONY_VENDOR_ID", "build_key_lookup",
    "normalize_key_name", "parse_ds4_usb_report", "parse_dualsense_usb_report", "state_from_glfw",
]
