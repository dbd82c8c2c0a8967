"""Window layouts: the built-in arrangements (in code), reading and writing layout files, and the
user's layout in the config directory.

A layout file is dearpygui's (Dear ImGui's) ini: ``[Window][###<id>]`` sections with ``Pos`` and
``Size`` keyed by the fixed window ids of :data:`app.panels.common.WINDOWS`, plus docking data, plus
one section of ours that ImGui ignores::

    [LmmStudio][Layout]
    Viewport=1600,900
    Hidden=stats,recording

At start the chosen file is handed to dearpygui (positions, sizes and docking are restored) and
windows it lists as hidden are not shown; switching layouts while running moves and resizes the
windows from the file (scaled to the current viewport). ``layouts/*.ini`` are generated from
:data:`BUILTIN` by ``lmm-studio --write-layouts layouts``.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

from lmm.errors import InputError

from . import layout_ini
from .panels.common import WINDOWS

REFERENCE_SIZE = (1600, 900)
MENU_HEIGHT = 22

# Accepted ranges of the numbers in a layout file (a value outside refuses the file, so the default
# layout is used instead of a studio that cannot start):
#: largest window or viewport side in pixels: an 8K display is 7680 x 4320, and the 3D view allocates
#: a framebuffer (and a float32 copy, 16 bytes a pixel) of its window's size, which at 8192 x 8192 is
#: already 1 GiB; every OpenGL 3.3 driver in use allows 8192 x 8192 render targets.
MAX_SIDE_PX = 8192
#: a window may sit partly off screen, but not further away than one largest display
MAX_POS_PX = 8192
#: the smallest viewport a layout can have been saved at: the layouts scale by viewport / reference,
#: and the studio's own minimum window is larger than this
MIN_VIEWPORT = (320, 240)
#: largest layout file read: ours are ~3 KB (13 windows, a few tables)
MAX_LAYOUT_BYTES = 1 << 20
LAYOUT_DIR = Path(__file__).resolve().parents[1] / "layouts"

#: where a window a built-in layout hides opens when shown (Windows menu, a Search Candidates click):
#: over the panels below or beside the 3D view, never over it or Tuning (they opened where another
#: layout had left them: the Database window over Tuning and the 3D view)
_BELOW_VIEW, _RIGHT_LOWER = (320, 522, 770, 378), (1090, 512, 510, 388)
OPENS_AT = {"default": {"database": _BELOW_VIEW, "coverage": _BELOW_VIEW, "motion_search": _BELOW_VIEW,
                        "physics": _RIGHT_LOWER}}

# name -> window key -> (x, y, width, height) at 1600x900, or None for hidden
BUILTIN: dict[str, dict[str, tuple[int, int, int, int] | None]] = {
    "default": {
        "tuning": (0, 22, 320, 578),
        "recording": (0, 600, 320, 300),
        "viewport": (320, 22, 770, 500),
        "timeline": (320, 522, 770, 130),
        "features": (320, 652, 770, 248),
        "search": (1090, 22, 510, 300),
        "candidates": (1090, 322, 510, 190),
        "latent": (1090, 512, 510, 228),
        "stats": (1090, 740, 510, 160),
        "database": None,
        "coverage": None,
        "motion_search": None,
        "physics": None,
    },
    "compare": {
        "viewport": (0, 22, 1040, 560),
        "search": (1040, 22, 560, 360),
        "candidates": (1040, 382, 560, 200),
        "features": (0, 582, 640, 318),
        "latent": (640, 582, 560, 318),
        "timeline": (1200, 582, 400, 160),
        "stats": (1200, 742, 400, 158),
        "tuning": None,
        "recording": None,
        "database": None,
        "coverage": None,
        "motion_search": None,
        "physics": None,
    },
    "tuning": {
        "tuning": (0, 22, 560, 878),
        "viewport": (560, 22, 1040, 520),
        "features": (560, 542, 620, 358),
        "timeline": (1180, 542, 420, 130),
        "stats": (1180, 672, 420, 228),
        "search": None,
        "candidates": None,
        "latent": None,
        "recording": None,
        "database": None,
        "coverage": None,
        "motion_search": None,
        "physics": None,
    },
    # the data workbench: browse the database, see its coverage, search motion by example
    "data": {
        "database": (0, 22, 430, 878),
        "viewport": (430, 22, 750, 520),
        "timeline": (430, 542, 750, 130),
        "motion_search": (430, 672, 750, 228),
        "coverage": (1180, 22, 420, 878),
        "features": None,
        "latent": None,
        "search": None,
        "candidates": None,
        "tuning": None,
        "stats": None,
        "recording": None,
        "physics": None,
    },
}


class LayoutError(InputError):
    """A layout name or file that cannot be used; the message says which and why."""


@dataclass
class Layout:
    name: str
    path: Path | None
    windows: dict = field(default_factory=dict)   # key -> {"pos": (x, y), "size": (w, h), "docked": bool}
    hidden: set = field(default_factory=set)
    reference_size: tuple[int, int] = REFERENCE_SIZE


def user_config_dir() -> Path:
    """``$LMM_STUDIO_CONFIG``, else ``$XDG_CONFIG_HOME/lmm-studio``, else ``~/.config/lmm-studio``."""
    env = os.environ.get("LMM_STUDIO_CONFIG")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CONFIG_HOME")
    from lmm.data.cache import home_dir

    return (Path(xdg) if xdg else home_dir() / ".config") / "lmm-studio"


def user_layout_path() -> Path:
    return user_config_dir() / "layout.ini"


def builtin_names() -> list[str]:
    return list(BUILTIN)


def resolve(name_or_path: str) -> Path:
    """A built-in layout name (``default``, ``compare``, ``tuning``, ``data``) or a file path -> the file."""
    s = str(name_or_path)
    if s in BUILTIN:
        p = LAYOUT_DIR / f"{s}.ini"
        if not p.is_file():
            raise LayoutError(f"the built-in layout {s!r} is missing ({p}); regenerate it with "
                              f"'lmm-studio --write-layouts {LAYOUT_DIR}'")
        return p
    try:
        p = Path(s).expanduser()
    except RuntimeError:   # "~" with no home folder: the name as given
        p = Path(s)
    if not p.is_file():
        known = ", ".join(BUILTIN)
        raise LayoutError(f"{s}: no such layout file (built-in layouts: {known})")
    return p


_SECTION = re.compile(r"^\[(?P<type>[^\]]*)\]\[(?P<name>.*)\]\s*$")


def parse(text: str, name: str = "layout", path: Path | None = None) -> Layout:
    """Read a layout ini. Raises :class:`LayoutError` when it holds none of the studio's windows or a
    window entry is malformed."""
    by_id = {str(tag): key for key, (tag, _) in WINDOWS.items()}
    where = str(path) if path else name
    if "\x00" in text:
        raise LayoutError(f"{where}: not a layout file (binary data)")
    layout = Layout(name=name, path=path)
    section = None
    current = None
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith(";"):
            continue
        m = _SECTION.match(line)
        if m:
            section = (m.group("type"), m.group("name"))
            current = None
            if section[0] == "Window":
                wid = section[1].split("###")[-1] if "###" in section[1] else None
                if wid in by_id:
                    current = layout.windows.setdefault(by_id[wid], {"pos": None, "size": None, "docked": False})
            continue
        if line.startswith("[") and section is None:
            raise LayoutError(f"{where}: line {lineno}: not an ini section header: {line[:60]!r}")
        if "=" not in line:
            if section is None:
                raise LayoutError(f"{where}: line {lineno}: expected 'key=value' or a [section], got {line[:60]!r}")
            continue
        key, _, value = line.partition("=")
        key, value = key.strip(), value.strip()
        if section == ("LmmStudio", "Layout"):
            if key == "Hidden":
                layout.hidden = {k.strip() for k in value.split(",") if k.strip() in WINDOWS}
            elif key == "Viewport":
                layout.reference_size = _pair(value, where, lineno, key, MIN_VIEWPORT, (MAX_SIDE_PX,) * 2)
            continue
        if current is None:
            continue
        if key == "Pos":
            current["pos"] = _pair(value, where, lineno, key, (-MAX_POS_PX,) * 2, (MAX_POS_PX,) * 2)
        elif key == "Size":
            current["size"] = _pair(value, where, lineno, key, (1, 1), (MAX_SIDE_PX,) * 2)
        elif key == "DockId":
            current["docked"] = True
    if section is None:
        raise LayoutError(f"{where}: not a layout file (no [Window] sections)")
    if not layout.windows:
        raise LayoutError(f"{where}: none of the studio's windows is in this layout file")
    try:   # every other section and key, before dearpygui (ImGui) trusts them (see app.layout_ini)
        layout_ini.check(text)
    except layout_ini.IniError as e:
        raise LayoutError(f"{where}: {e}") from None
    return layout


def _pair(value: str, where, lineno, key, low, high) -> tuple[int, int]:
    """Two numbers ``a,b`` with ``low[i] <= v <= high[i]`` (ranges above), as ints."""
    try:
        pair = [float(v) for v in value.split(",")]
    except ValueError:
        pair = []
    if len(pair) != 2 or not all(math.isfinite(v) for v in pair):
        raise LayoutError(f"{where}: line {lineno}: {key} must be two numbers 'x,y', got {value[:60]!r}")
    for v, lo, hi in zip(pair, low, high):
        if not lo <= v <= hi:
            raise LayoutError(f"{where}: line {lineno}: {key}={value[:60]} is out of range "
                              f"({lo}..{hi} on each side)")
    return int(pair[0]), int(pair[1])


def load(name_or_path: str) -> Layout:
    from lmm.data.reading import read_limited

    path = resolve(name_or_path)
    try:
        text = read_limited(path, MAX_LAYOUT_BYTES, "layout file").decode("utf-8")
    except UnicodeDecodeError:
        raise LayoutError(f"{path}: not a layout file (not UTF-8 text)") from None
    except InputError as e:   # a FIFO, a device, a file far larger than any layout
        raise LayoutError(str(e)) from None
    except OSError as e:
        raise LayoutError(f"{path}: cannot read ({e.strerror})") from None
    name = name_or_path if name_or_path in BUILTIN else path.stem
    layout = parse(text, name=name, path=path)
    # a shipped layout's hidden windows open where OPENS_AT says (dearpygui writes no place for a
    # window that was never shown, so the file holds a place another layout left)
    for key, (x, y, w, h) in OPENS_AT.get(name if name_or_path in BUILTIN else "", {}).items():
        if key in layout.hidden:
            layout.windows[key] = {"pos": (x, y), "size": (w, h), "docked": False}
    return layout


def from_builtin(name: str) -> Layout:
    """A built-in arrangement straight from :data:`BUILTIN` (no file); a hidden window with a place in
    :data:`OPENS_AT` is put there, hidden, so that showing it never covers the 3D view."""
    spec = BUILTIN[name]
    layout = Layout(name=name, path=None)
    for key, rect in spec.items():
        if rect is None:
            layout.hidden.add(key)
            rect = OPENS_AT.get(name, {}).get(key)
        if rect is not None:
            x, y, w, h = rect
            layout.windows[key] = {"pos": (x, y), "size": (w, h), "docked": False}
    return layout


def scaled(rect_pos, rect_size, reference, viewport) -> tuple[tuple[int, int], tuple[int, int]]:
    """Positions and sizes scaled from the layout's viewport size to the current one (below the menu)."""
    rw, rh = reference
    vw, vh = viewport
    sx = vw / max(rw, 1)
    sy = (vh - MENU_HEIGHT) / max(rh - MENU_HEIGHT, 1)
    x, y = rect_pos
    w, h = rect_size
    nx = int(round(x * sx))
    ny = int(round(MENU_HEIGHT + (y - MENU_HEIGHT) * sy)) if y >= MENU_HEIGHT else int(y)
    # never larger than the viewport (nor than MAX_SIDE_PX): a window's 3D view allocates its size
    nw = min(max(int(round(w * sx)), 80), max(int(vw), 80), MAX_SIDE_PX)
    nh = min(max(int(round(h * sy)), 60), max(int(vh), 60), MAX_SIDE_PX)
    return (nx, ny), (nw, nh)


def extra_section(hidden, viewport) -> str:
    return (f"\n[LmmStudio][Layout]\nViewport={int(viewport[0])},{int(viewport[1])}\n"
            f"Hidden={','.join(sorted(hidden))}\n")


def strip_extra_section(text: str) -> str:
    out, skip = [], False
    for line in text.splitlines():
        if _SECTION.match(line.strip()):
            skip = line.strip() == "[LmmStudio][Layout]"
        if not skip:
            out.append(line)
    return "\n".join(out).rstrip() + "\n"
