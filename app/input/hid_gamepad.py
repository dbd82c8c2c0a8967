"""Sony DualShock 4 and DualSense over USB, read directly through hidapi.

Report layouts (USB input report 0x01, 64 bytes; offsets count the report id as byte 0):

DualShock 4 (product ids 0x05C4 v1, 0x09CC v2)::

    0  report id 0x01
    1  left stick x    2  left stick y    3  right stick x    4  right stick y    (0..255, 128 centred, y down)
    5  bits 0-3 hat (0 = north, clockwise; 8 = centred), bit 4 square, 5 cross, 6 circle, 7 triangle
    6  bit 0 L1, 1 R1, 2 L2, 3 R2, 4 share, 5 options, 6 L3, 7 R3
    7  bit 0 PS, bit 1 touchpad click, bits 2-7 report counter
    8  L2 analog (0..255)    9  R2 analog

DualSense (product ids 0x0CE6, Edge 0x0DF2)::

    0  report id 0x01
    1  left stick x    2  left stick y    3  right stick x    4  right stick y
    5  L2 analog       6  R2 analog       7  report counter
    8  bits 0-3 hat, bit 4 square, 5 cross, 6 circle, 7 triangle
    9  bit 0 L1, 1 R1, 2 L2, 3 R2, 4 create, 5 options, 6 L3, 7 R3
    10 bit 0 PS, bit 1 touchpad click, bit 2 mute

The parsers need only those leading bytes (10 for the DualShock 4, 11 for the DualSense); the
DualSense's 10-byte Bluetooth "simple" report, which has another layout, is refused by its length.

Sticks map 0 -> -1, 128 -> 0, 255 -> +1 (the negative half has 128 steps, the positive 127), with y
negated so that up is +1; triggers map 0..255 to 0..1.

:class:`HIDGamepad` opens the first known pad, reads it without blocking and never raises: a read
error (the pad was unplugged) closes it and it looks for a pad again at most every ``rescan_interval``
seconds. Reading needs permission on the device node (on Linux a udev rule for /dev/hidraw*).
"""
from __future__ import annotations

import time
from typing import Callable

from ..jobs import Job, Jobs, one_line
from .state import HAT_CENTRED, GamepadState, hat_buttons

SONY_VENDOR_ID = 0x054C
KNOWN_PRODUCTS: dict[int, tuple[str, str]] = {   # product id -> (kind, display name)
    0x05C4: ("ds4", "DualShock 4"),
    0x09CC: ("ds4", "DualShock 4 (v2)"),
    0x0CE6: ("dualsense", "DualSense"),
    0x0DF2: ("dualsense", "DualSense Edge"),
}
REPORT_ID_USB = 0x01
DS4_MIN_LENGTH = 10
DUALSENSE_MIN_LENGTH = 11
USB_REPORT_LENGTH = 64
BUS_TYPE_BLUETOOTH = 2   # hidapi >= 0.14 'bus_type' (1 USB, 2 Bluetooth)


class HIDReportError(ValueError):
    """A report that is not a USB input report of the expected pad (raised only with ``strict=True``)."""


def _axis(v: int) -> float:
    d = int(v) - 128
    return d / 128.0 if d < 0 else d / 127.0


def _as_bytes(data) -> bytes:
    if data is None:
        raise HIDReportError("no report")
    try:
        return bytes(data)
    except (TypeError, ValueError) as e:
        raise HIDReportError(f"not a byte sequence: {e}") from None


def _check(raw: bytes, min_length: int, what: str) -> None:
    if len(raw) < min_length:
        raise HIDReportError(f"{what} report too short: {len(raw)} bytes, need at least {min_length}")
    if raw[0] != REPORT_ID_USB:
        raise HIDReportError(f"{what} report id 0x{raw[0]:02x}, expected 0x{REPORT_ID_USB:02x} (USB input report)")


def _buttons(face: int, shoulders: int, system: int, mute: bool) -> frozenset:
    hat = face & 0x0F
    names = hat_buttons(hat)
    for bit, name in ((4, "west"), (5, "south"), (6, "east"), (7, "north")):
        if face >> bit & 1:
            names.add(name)
    for bit, name in ((0, "l1"), (1, "r1"), (2, "l2"), (3, "r2"), (4, "select"), (5, "start"), (6, "l3"), (7, "r3")):
        if shoulders >> bit & 1:
            names.add(name)
    if system & 0x01:
        names.add("home")
    if system & 0x02:
        names.add("touchpad")
    if mute and system & 0x04:
        names.add("mute")
    return frozenset(names)


def _state(raw: bytes, l2: int, r2: int, face: int, shoulders: int, system: int, mute: bool) -> GamepadState:
    hat = face & 0x0F
    return GamepadState(left_x=_axis(raw[1]), left_y=0.0 - _axis(raw[2]),   # 0.0 - x: no -0.0 at centre
                        right_x=_axis(raw[3]), right_y=0.0 - _axis(raw[4]),
                        left_trigger=l2 / 255.0, right_trigger=r2 / 255.0,
                        buttons=_buttons(face, shoulders, system, mute),
                        hat=hat if hat < 8 else HAT_CENTRED)


def parse_ds4_usb_report(data, strict: bool = False) -> GamepadState | None:
    """A DualShock 4 USB input report (bytes, bytearray or hidapi's list of ints) -> state.

    Malformed data (empty, too short, wrong report id, not bytes) gives ``None``, or raises
    :class:`HIDReportError` when ``strict``.
    """
    try:
        raw = _as_bytes(data)
        _check(raw, DS4_MIN_LENGTH, "DualShock 4")
        return _state(raw, raw[8], raw[9], raw[5], raw[6], raw[7], mute=False)
    except HIDReportError:
        if strict:
            raise
        return None


def parse_dualsense_usb_report(data, strict: bool = False) -> GamepadState | None:
    """A DualSense (or DualSense Edge) USB input report -> state; see :func:`parse_ds4_usb_report`."""
    try:
        raw = _as_bytes(data)
        _check(raw, DUALSENSE_MIN_LENGTH, "DualSense")
        return _state(raw, raw[5], raw[6], raw[8], raw[9], raw[10], mute=True)
    except HIDReportError:
        if strict:
            raise
        return None


PARSERS = {"ds4": parse_ds4_usb_report, "dualsense": parse_dualsense_usb_report}


def _import_hid():
    try:
        import hid  # hidapi's module
        return hid
    except Exception:
        return None


class HIDGamepad:
    """Polls one Sony pad over hidapi. ``poll()`` never raises and never blocks.

    ``hid_module``: the ``hid`` module (default) or a stand-in with ``enumerate(vendor_id=...)`` and
    ``device()`` (whose objects have ``open_path``, ``set_nonblocking``, ``read(n)``, ``close``).
    ``None`` or a failed import leaves the poller permanently disconnected.
    ``background_scan``: enumerate as a background job (:mod:`app.jobs`; default: only with the real
    module, so that stand-ins in tests stay synchronous); the device is always opened and read on the
    caller's thread.
    """

    def __init__(self, hid_module="auto", rescan_interval: float = 1.0, stale_timeout: float = 1.0,
                 clock: Callable[[], float] = time.monotonic, max_reads_per_poll: int = 64,
                 background_scan: bool | None = None):
        self._hid = _import_hid() if hid_module == "auto" else hid_module
        # enumerating walks every HID device of the system (milliseconds with many devices): with the
        # real module it runs as a background job (app.jobs) so the frame loop never waits for it
        self.background_scan = (hid_module == "auto") if background_scan is None else bool(background_scan)
        self._jobs = Jobs()
        self._scan_job: Job | None = None
        self._scan_result = None
        self.rescan_interval = float(rescan_interval)
        self.stale_timeout = float(stale_timeout)
        self._clock = clock
        self.max_reads_per_poll = int(max_reads_per_poll)
        self._dev = None
        self._info: dict | None = None
        self._kind: str | None = None
        self._last_scan = -float("inf")
        self._last_report_t = 0.0
        self.state: GamepadState | None = None
        self.name: str = ""
        self.path = None
        self.bad_reports = 0
        self.last_error: str = ""
        self.events: list[str] = []   # "connected: NAME" / "disconnected: NAME (why)"; the owner may clear it

    @property
    def available(self) -> bool:
        """hidapi could be imported (devices may still be absent)."""
        return self._hid is not None

    @property
    def connected(self) -> bool:
        return self._dev is not None

    @property
    def product_id(self) -> int | None:
        """USB product id of the open pad, None when none is open."""
        return int(self._info["product_id"]) if self._info is not None else None

    # ---- device discovery ---------------------------------------------------------------------
    def _enumerate(self) -> list[dict]:
        found = self._hid.enumerate(vendor_id=SONY_VENDOR_ID)
        out = []
        for info in found or ():
            try:
                if int(info.get("vendor_id", SONY_VENDOR_ID)) != SONY_VENDOR_ID:
                    continue
                if int(info.get("product_id", -1)) not in KNOWN_PRODUCTS:
                    continue
                if info.get("bus_type") == BUS_TYPE_BLUETOOTH:
                    continue   # Bluetooth reports have other layouts
                out.append(info)
            except (AttributeError, TypeError, ValueError):
                continue
        return out

    def _took_scan(self, result) -> None:
        self._scan_result = result

    def _scan(self, now: float):
        """The candidates of the latest finished scan (a list, or one line saying why it failed), or None
        while no result is ready. Starts a scan when none ran for ``rescan_interval`` seconds."""
        if self._scan_job is not None:
            if not self._scan_job.finished:
                return None
            self._scan_job = None
            self._jobs.poll()
            result, self._scan_result = self._scan_result, None
            return result
        if now - self._last_scan < self.rescan_interval:
            return None
        self._last_scan = now
        if not self.background_scan:
            try:
                return self._enumerate()
            except Exception as e:   # hidapi errors are OSError; a stand-in could raise anything
                return one_line(e)
        # the outcome (a list, or the one line of a failure) is taken by a later call
        self._scan_job = self._jobs.submit("hid-gamepad-scan", lambda job: self._enumerate(),
                                           on_done=self._took_scan, on_error=self._took_scan)
        return None

    def _try_open(self, now: float) -> None:
        candidates = self._scan(now)
        if candidates is None:
            return
        if isinstance(candidates, str):
            self.last_error = f"enumerate: {candidates}"
            return
        for info in candidates:
            dev = None
            try:
                dev = self._hid.device()
                dev.open_path(info["path"])
                dev.set_nonblocking(1)    # a blocking read would freeze the frame loop: never skip this
            except Exception as e:
                self.last_error = f"open: {e}"
                self._close_quietly(dev)
                continue
            pid = int(info["product_id"])
            self._dev, self._info = dev, info
            self._kind, self.name = KNOWN_PRODUCTS[pid]
            self.name = f"{self.name} (USB HID)"
            self.path = info["path"]
            self._last_report_t = now
            self.state = None
            self.events.append(f"connected: {self.name}")
            return

    @staticmethod
    def _close_quietly(dev) -> None:
        if dev is None:
            return
        try:
            dev.close()
        except Exception:
            pass

    def _disconnect(self, why: str, now: float) -> None:
        self._close_quietly(self._dev)
        if self._dev is not None:
            self.events.append(f"disconnected: {self.name} ({why})")
        self._dev = self._info = self._kind = None
        self.state = None
        self.path = None
        self.last_error = why
        self._last_scan = now      # the next look for a pad comes rescan_interval later

    # ---- polling ------------------------------------------------------------------------------
    def poll(self) -> GamepadState | None:
        """Read every pending report; return the newest state, or None when no pad is usable."""
        try:
            return self._poll()
        except Exception as e:     # never let a backend problem reach the frame loop
            self._disconnect(f"error: {e}", self._clock())
            return None

    def _poll(self) -> GamepadState | None:
        now = self._clock()
        if self._hid is None:
            return None
        if self._dev is None:
            self._try_open(now)
            if self._dev is None:
                return None
        parse = PARSERS[self._kind]
        got_report = False
        for _ in range(self.max_reads_per_poll):
            try:
                data = self._dev.read(USB_REPORT_LENGTH)
            except (OSError, ValueError) as e:   # unplugged (IOError is OSError) / handle closed
                self._disconnect(f"read failed: {e}", now)
                return None
            if not data:
                break
            st = parse(data)
            if st is None:
                self.bad_reports += 1
                continue
            self.state, got_report = st, True
        if got_report:
            self._last_report_t = now
        elif now - self._last_report_t > self.stale_timeout:
            # USB pads report continuously (~250 Hz): a long silence means unplugged (some platforms
            # never fail the read) or a pad that sends something else. Drop the stale state, and check
            # whether the device is still there (at most every rescan_interval).
            self.state = None
            found = self._scan(now)
            if found is not None and (isinstance(found, Exception)
                                      or not any(i.get("path") == self.path for i in found)):
                self._disconnect("gone", now)
                return None
        return self.state

    def close(self) -> None:
        self._disconnect("closed", self._clock())
