"""Window layouts while the studio runs: choosing the one to start with, applying one (moving, sizing,
showing and hiding the panels' windows), switching and saving. The file format is
:mod:`app.layout_files`.

A saved user layout never locks the studio in a crash loop: one that cannot be read or applied is
reported, set aside as ``layout.ini.bad`` and replaced by the default; and a start with the user
layout leaves a marker (``layout.ini.starting``) until its first frames are drawn, so a start that
died with it (a crash the checks did not foresee) sets it aside on the next start. A save leaves
``layout.ini.saving`` while dearpygui writes its state: a studio that crashed or hung (and was killed)
inside that writer has its saved layout set aside at the next start. What is saved is checked by the
same reader first (:mod:`app.layout_ini`): a layout no start could use is never written.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable

from . import layout_files
from .layout_files import Layout, LayoutError
from .panels.common import built_windows, window_tag

FALLBACK_RECT = {"pos": (40, 60), "size": (400, 300)}


class LayoutManager:
    def __init__(self, dpg, report_error: Callable[[str, str], None], default_size: tuple[int, int]):
        self.dpg = dpg
        self.report_error = report_error
        self.default_size = default_size
        self.layout: Layout | None = None
        self.switches: list[dict] = []          # {"frame", "layout"} for the test dump
        self._working_ini: Path | None = None
        self._starting_marker: Path | None = None
        self._shown: dict[str, bool] = {}       # window key -> shown, as last asked of dearpygui

    @property
    def name(self) -> str:
        return self.layout.name if self.layout is not None else "default"

    # -- start-up ------------------------------------------------------------------------------
    def choose(self, requested: str | None) -> str:
        """Pick the start layout (``requested``, else the user's last one, else the default) and return
        the ini file to hand dearpygui: a private copy, since dearpygui may write it back while running."""
        candidates = []
        user = layout_files.user_layout_path()
        marker = _marker(user)
        saving = _marker(user, ".saving")
        if saving.exists():   # the last save died inside dearpygui: what it had saved before is suspect too
            if user.is_file():
                self._set_aside(user, "the studio ended while saving it (a crash or a hang in the layout writer)")
            saving.unlink(missing_ok=True)
        if requested:
            candidates.append(("--layout", requested))
        elif user.is_file():
            if marker.exists():
                self._set_aside(user, "the last start with it did not finish drawing its first frame")
            else:
                candidates.append(("user", str(user)))
        candidates.append(("default", "default"))
        self.layout = None
        for origin, spec in candidates:
            try:
                self.layout = layout_files.load(spec)
                if origin == "user":
                    self.layout.name = "user"
                    self._starting_marker = marker
                    _touch(marker)
                break
            except LayoutError as e:
                if origin == "user":
                    self._set_aside(user, str(e))
                else:
                    self.report_error("Layout", f"{e} - using the default layout instead")
        if self.layout is None:
            self.layout = layout_files.from_builtin("default")
        work = Path(tempfile.mkdtemp(prefix="lmm-studio-")) / "session.ini"
        text = ""
        if self.layout.path is not None:
            text = layout_files.strip_extra_section(Path(self.layout.path).read_text(encoding="utf-8",
                                                                                      errors="replace"))
        work.write_text(text, encoding="utf-8")
        self._working_ini = work
        return str(work)

    def _set_aside(self, user: Path, why: str) -> None:
        """Move a saved user layout that cannot be used to ``layout.ini.bad`` and say so."""
        bad = user.with_name(user.name + ".bad")
        try:
            os.replace(user, bad)
            where = f"moved to {bad}"
        except OSError as e:
            where = f"could not be moved aside ({e.strerror})"
        _marker(user).unlink(missing_ok=True)
        self.report_error("Layout", f"the saved layout {user} cannot be used ({why}); it was {where} "
                                    f"and the default layout is used instead")

    def window_kwargs(self, key: str) -> dict:
        """Where a panel's window starts (before the ini file, if any, places it)."""
        code = layout_files.from_builtin("default")
        rect = self.layout.windows.get(key) or code.windows.get(key) or FALLBACK_RECT
        w, h = rect["size"] or FALLBACK_RECT["size"]
        return dict(pos=rect["pos"] or FALLBACK_RECT["pos"], width=w, height=h,
                    show=key not in self.layout.hidden and key in self.layout.windows, no_collapse=False)

    def settle(self) -> None:
        """After the first frame: scale the start layout to the window unless dearpygui restored it.
        The start is then known to work: the user layout's start marker is removed."""
        if self.layout.path is None or tuple(self.layout.reference_size) != self._viewport_size():
            try:
                self.apply(self.layout, at_start=True)
            except Exception as e:   # never a studio that cannot start because of a layout
                self.report_error("Layout", f"{self.layout.path or self.layout.name}: cannot be applied "
                                            f"({type(e).__name__}: {e}) - using the default layout instead")
                self.apply(layout_files.from_builtin("default"), at_start=True)

    def started(self) -> None:
        """The first frames were drawn with the start layout: remove the start marker."""
        if self._starting_marker is not None:
            self._starting_marker.unlink(missing_ok=True)
            self._starting_marker = None

    def close(self) -> None:
        if self._working_ini is not None:
            shutil.rmtree(self._working_ini.parent, ignore_errors=True)

    # -- while running -------------------------------------------------------------------------
    def _viewport_size(self) -> tuple[int, int]:
        dpg = self.dpg
        return (dpg.get_viewport_client_width() or self.default_size[0],
                dpg.get_viewport_client_height() or self.default_size[1])

    def switch(self, name_or_path: str, frame: int = -1) -> bool:
        try:
            layout = layout_files.load(name_or_path)
        except LayoutError as e:
            self.report_error("Layout", str(e))
            return False
        self.apply(layout)
        self.switches.append({"frame": frame, "layout": layout.name})
        return True

    def apply(self, layout: Layout, at_start: bool = False) -> None:
        dpg = self.dpg
        self.forget_shown()
        viewport = self._viewport_size()
        for key in built_windows(dpg):
            tag = window_tag(key)
            rect = layout.windows.get(key)
            dpg.configure_item(tag, show=key not in layout.hidden and rect is not None)
            if rect is not None and rect.get("docked") and at_start:
                continue  # docked at start: dearpygui restored the dock node from the file already
            if rect is not None and rect.get("pos") is not None and rect.get("size") is not None:
                pos, size = layout_files.scaled(rect["pos"], rect["size"], layout.reference_size, viewport)
                dpg.set_item_pos(tag, pos)
                dpg.configure_item(tag, width=size[0], height=size[1])
        self.layout = layout

    def save(self, path: str) -> bool:
        """Write the current layout to ``path`` atomically (a crash or a full disk never leaves half a
        layout, which would be the next start's layout); a failure is reported, not raised."""
        from lmm.data.atomic import write_text_atomic

        dpg = self.dpg
        path = Path(path)
        scratch = None
        self.forget_shown()     # what dearpygui shows now, not what a recent frame saw
        saving = _marker(path, ".saving")   # left behind only if ImGui's writer crashed or hung
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            _touch(saving)
            scratch = Path(tempfile.mkdtemp(prefix="lmm-studio-save-")) / "layout.ini"
            dpg.save_init_file(str(scratch))
            text = layout_files.strip_extra_section(scratch.read_text(encoding="utf-8", errors="replace"))
            text += layout_files.extra_section(self.hidden(), self._viewport_size())
            layout_files.parse(text, name=path.stem, path=path)   # what is saved is read back the same way
            write_text_atomic(path, text)
        except LayoutError as e:   # ImGui's state holds something no start may be handed: keep the old file
            self.report_error("Layout", f"not saved: {e}")
            return False
        except OSError as e:
            self.report_error("Layout", f"{path}: cannot write ({e.strerror or e})")
            return False
        finally:
            if scratch is not None:
                shutil.rmtree(scratch.parent, ignore_errors=True)
            saving.unlink(missing_ok=True)
        return True

    def show_window(self, key: str, show: bool) -> None:
        self.dpg.configure_item(window_tag(key), show=bool(show))
        self._shown.pop(key, None)

    def shown(self, key: str) -> bool:
        """Whether window ``key`` is shown, remembered between frames: dearpygui's answer builds the
        window's whole configuration (several microseconds a window, each frame). What this manager shows
        or hides is forgotten at once; the studio forgets the rest (:meth:`forget_shown`) after any
        callback (a menu check, a layout) and every few frames (a window closed by its own x button)."""
        found = self._shown.get(key)
        if found is None:
            found = self._shown[key] = bool(self.dpg.is_item_shown(window_tag(key)))
        return found

    def forget_shown(self) -> None:
        self._shown.clear()

    def hidden(self) -> list[str]:
        """Keys of the windows not shown now."""
        return [k for k in built_windows(self.dpg) if not self.shown(k)]

    def window_state(self) -> dict:
        dpg = self.dpg
        return {key: {"pos": list(dpg.get_item_pos(window_tag(key))),
                      "size": [dpg.get_item_width(window_tag(key)), dpg.get_item_height(window_tag(key))],
                      "shown": bool(dpg.is_item_shown(window_tag(key)))} for key in built_windows(dpg)}


def _marker(user_layout: Path, kind: str = ".starting") -> Path:
    return user_layout.with_name(user_layout.name + kind)


def _touch(path: Path) -> None:
    try:
        path.write_text("the studio is starting with the layout beside this file\n", encoding="utf-8")
    except OSError:
        pass   # a read-only config folder: no crash-loop guard, nothing else changes
