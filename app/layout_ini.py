"""The grammar of a layout file, checked line by line before dearpygui (Dear ImGui) ever reads it.

ImGui trusts its ini file: a ``[Table]`` section declaring 2e9 columns made it allocate until it
crashed (``Segmentation fault``), and one with 1e8 columns let the studio start at 3.3 GB and then
save a negative count that crashed or hung every later start in ImGui's ini writer. So every section
and key the studio's files hold is known here with the range its numbers may take; anything else (an
unknown section or key, a number out of range, a malformed value) refuses the whole file with one line
naming the file, line and key, and the studio starts with the default layout instead. What the studio
saves is checked the same way before it is written.

Sections: ``[Window][NAME]`` (Pos, Size, Collapsed, DockId, ViewportId, ViewportPos, ClassId, IsChild),
``[Table][0xID,COLUMNS]`` (RefScale, ``Column N`` with UserID, Width, Weight, Visible, Order, Sort),
``[Docking][Data]`` (``DockSpace``/``DockNode`` lines of key=value fields) and our ``[LmmStudio][Layout]``.
"""
from __future__ import annotations

import math
import re

#: most columns a table may declare: our widest table has 14; ImGui's own limit is 64 (512 in 1.90)
MAX_TABLE_COLUMNS = 64
#: a font reference scale (pixels): ImGui writes the font size the table was sized with
MAX_REF_SCALE = 1000.0
#: pixel positions and sizes (see app.layout_files: MAX_SIDE_PX, MAX_POS_PX)
MAX_PX = 8192

_HEX = re.compile(r"^0x[0-9A-Fa-f]{1,8}$")
_INT = re.compile(r"^[+-]?[0-9]{1,10}$")
_TABLE_NAME = re.compile(r"^(0x[0-9A-Fa-f]{1,8}),([+-]?[0-9]{1,12})$")
_COLUMN = re.compile(r"^Column\s+([0-9]{1,6})((?:\s+\S+)*)$")
_SECTIONS = ("Window", "Table", "Docking", "LmmStudio")


class IniError(ValueError):
    """One problem of a layout file's line: ``str()`` is "line N: what"."""


def _int(value: str, lo: int, hi: int, what: str) -> int:
    if not _INT.match(value) or not lo <= int(value) <= hi:
        raise IniError(f"{what}={value[:40]} must be an integer from {lo} to {hi}")
    return int(value)


def _float(value: str, lo: float, hi: float, what: str) -> float:
    try:
        v = float(value) if value.isascii() and "_" not in value else math.nan
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and lo <= v <= hi):
        raise IniError(f"{what}={value[:40]} must be a number from {lo:g} to {hi:g}")
    return v


def _pair(value: str, lo: int, hi: int, what: str) -> None:
    parts = value.split(",")
    if len(parts) != 2:
        raise IniError(f"{what}={value[:40]} must be two integers 'x,y'")
    for p in parts:
        _int(p.strip(), lo, hi, what)


def _hex(value: str, what: str) -> None:
    if not _HEX.match(value):
        raise IniError(f"{what}={value[:40]} must be a hexadecimal id 0x...")


def _window_key(key: str, value: str) -> None:
    if key in ("Pos", "ViewportPos"):
        _pair(value, -MAX_PX, MAX_PX, key)
    elif key == "Size":
        _pair(value, 0, MAX_PX, key)
    elif key in ("Collapsed", "IsChild"):
        _int(value, 0, 1, key)
    elif key in ("ViewportId", "ClassId"):
        _hex(value, key)
    elif key == "DockId":
        ident, _, order = value.partition(",")
        _hex(ident, key)
        if order:
            _int(order, -1, 1000, key)
    else:
        raise IniError(f"unknown key {key[:40]!r} in a [Window] section")


def _column(line: str, columns: int) -> None:
    m = _COLUMN.match(line)
    if not m:
        raise IniError(f"expected 'Column N field=value ...', got {line[:60]!r}")
    _int(m.group(1), 0, columns - 1, "Column")
    for field in m.group(2).split():
        key, eq, value = field.partition("=")
        if not eq:
            raise IniError(f"expected field=value in a Column line, got {field[:40]!r}")
        if key == "UserID":
            _hex(value, key)
        elif key == "Width":
            _int(value, 0, MAX_PX, key)
        elif key == "Weight":
            _float(value, 0.0, 1e6, key)
        elif key == "Visible":
            _int(value, 0, 1, key)
        elif key == "Order":
            _int(value, 0, columns - 1, key)
        elif key == "Sort":
            if not value or value[-1] not in "v^":
                raise IniError(f"Sort={value[:40]} must be a sort order followed by v or ^")
            _int(value[:-1], 0, columns - 1, key)
        else:
            raise IniError(f"unknown field {key[:40]!r} in a Column line")


def _dock_line(line: str) -> None:
    words = line.split()
    if not words or words[0] not in ("DockSpace", "DockNode"):
        raise IniError(f"expected a DockSpace or DockNode line, got {line[:60]!r}")
    for field in words[1:]:
        key, eq, value = field.partition("=")
        if not eq:
            raise IniError(f"expected field=value in a {words[0]} line, got {field[:40]!r}")
        if key in ("ID", "Parent", "Window", "Selected"):
            _hex(value, key)
        elif key == "Pos":
            _pair(value, -MAX_PX, MAX_PX, key)
        elif key in ("Size", "SizeRef"):
            _pair(value, 0, MAX_PX, key)
        elif key == "Split":
            if value not in ("X", "Y"):
                raise IniError(f"Split={value[:40]} must be X or Y")
        elif key in ("NoResize", "CentralNode", "HiddenTabBar", "NoTabBar", "NoWindowMenuButton",
                     "NoCloseButton"):
            _int(value, 0, 1, key)
        else:
            raise IniError(f"unknown field {key[:40]!r} in a {words[0]} line")


def check(text: str) -> None:
    """Raise :class:`IniError` ("line N: ...") at the first line of ``text`` outside the grammar."""
    section = None
    columns = 0
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith(";"):
            continue
        try:
            if line.startswith("["):
                m = re.match(r"^\[([^\]]*)\]\[(.*)\]$", line)
                if not m or m.group(1) not in _SECTIONS:
                    raise IniError(f"unknown section {line[:60]!r} (known: {', '.join(_SECTIONS)})")
                section = m.group(1)
                if section == "Table":
                    t = _TABLE_NAME.match(m.group(2))
                    if not t:
                        raise IniError(f"expected [Table][0xID,COLUMNS], got {line[:60]!r}")
                    columns = _int(t.group(2), 1, MAX_TABLE_COLUMNS, "[Table] columns")
                elif section == "Docking" and m.group(2) != "Data":
                    raise IniError(f"unknown section {line[:60]!r}")
                elif section == "LmmStudio" and m.group(2) != "Layout":
                    raise IniError(f"unknown section {line[:60]!r}")
                continue
            if section is None:
                raise IniError(f"a line before any [section]: {line[:60]!r}")
            if section == "Docking":
                _dock_line(line)
                continue
            if section == "Table" and line.startswith("Column"):
                _column(line, columns)
                continue
            key, eq, value = line.partition("=")
            key, value = key.strip(), value.strip()
            if not eq:
                raise IniError(f"expected key=value, got {line[:60]!r}")
            if section == "Window":
                _window_key(key, value)
            elif section == "Table":
                if key != "RefScale":
                    raise IniError(f"unknown key {key[:40]!r} in a [Table] section")
                _float(value, 1.0, MAX_REF_SCALE, key)
            elif key not in ("Viewport", "Hidden"):   # [LmmStudio][Layout]: checked by app.layout_files
                raise IniError(f"unknown key {key[:40]!r} in the [LmmStudio][Layout] section")
        except IniError as e:
            raise IniError(f"line {lineno}: {e}") from None
