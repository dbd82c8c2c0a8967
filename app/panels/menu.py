"""The menu bar: files (input, reference BVH, presets, weights), layouts, window visibility, help,
and a status line (mode, fps, tick, last error), led by what needs the user's eye: the behind-real-time
note and the data-fit note (:class:`lmm.data_fit.DataFit`: speeds the tuning asks for beyond the database,
bone roles that look wrong; the whole lines in its tooltip). Its items are the commands that name a menu
(:mod:`app.studio_commands`); the keys help lists the commands' shortcuts."""
from __future__ import annotations

from app.layout_files import builtin_names

from app.command_registry import CommandRegistry
from app.input.manager import pad_buttons_help
from lmm.data_fit import DataFit

from .base import PanelContext, View
from .common import WINDOWS, TextCache, built_windows, window_tag

MENUS = ("File", "Edit", "Layout", "Windows", "Help")


def keys_help(commands: CommandRegistry) -> str:
    """The Help > Keys and mouse text: the character keys, then every command's shortcut."""
    shortcuts = [f"  {key:<19}{c.help or c.label}" for key, c in commands.shortcuts().items()]
    return "\n".join(["Keyboard (the 3D view does not need focus; text fields do take the keys):",
                      "  W A S D / arrows   move (camera relative)      Shift  walk        Ctrl  strafe",
                      "  I J K L            aim (right stick)           Q / E  turn the camera", *shortcuts,
                      "Mouse on the 3D view: left-drag orbit, right/middle-drag pan, wheel zoom.",
                      "Gamepads (glfw or raw HID): left stick move, right stick aim/camera, "
                      + pad_buttons_help() + "."])


def hidden_note(hidden) -> str:
    """The status line's note on hidden windows (empty when every window shows)."""
    if not hidden:
        return ""
    titles = ", ".join(WINDOWS[k][1] for k in WINDOWS if k in hidden)
    return f"hidden: {titles} (Windows menu shows them)"


class MenuBar:
    """Not a window: the viewport's menu bar. It lists the registry's commands, so it gets all of them."""
    reads = ("frame", "frame_times", "hidden_windows", "input_name", "layout", "mode", "problems", "recording",
             "tick_number")

    def __init__(self, ctx: PanelContext):
        self.ctx = ctx
        self.commands: CommandRegistry = ctx.commands
        self.dpg = ctx.dpg
        self.text = TextCache(ctx.dpg)
        self._fps = None        # (frame, fps) last worked out
        self.behind = lambda: ""    # the "behind real time" note (the studio sets it: app.realtime)
        self.data_fit = DataFit(ctx.engine.db)   # the database is the studio's for its whole run

    def build(self) -> None:
        dpg = self.dpg
        with dpg.viewport_menu_bar(tag="menu_bar"):
            with dpg.menu(label="File"):
                self._add_commands("File")
            with dpg.menu(label="Edit"):
                self._add_commands("Edit")
            with dpg.menu(label="Layout"):
                for name in builtin_names():
                    dpg.add_menu_item(label=name.capitalize(), callback=self._on_layout, user_data=name,
                                      tag=f"menu_layout_{name}")
                dpg.add_separator()
                self._add_commands("Layout")
            with dpg.menu(label="Windows"):
                for key, (tag, title) in WINDOWS.items():
                    dpg.add_menu_item(label=title, check=True, default_value=True, tag=f"menu_show_{key}",
                                      callback=self._on_show, user_data=key)
            with dpg.menu(label="Help"):
                self._add_commands("Help")
            dpg.add_spacer(width=30)
            dpg.add_text("", tag="menu_behind", color=(255, 170, 90))
            with dpg.tooltip("menu_behind"):
                dpg.add_text("Simulated time over wall time of the last 3 s: the machine cannot step the\n"
                             "characters as fast as the clock runs (or a script steps one tick a frame)")
            dpg.add_text("", tag="menu_data_fit", color=(255, 170, 90))
            with dpg.tooltip("menu_data_fit"):
                dpg.add_text("", tag="menu_data_fit_lines", wrap=640)
            dpg.add_text("", tag="menu_status", color=(170, 200, 170))

    def _add_commands(self, menu: str) -> None:
        """The commands that name ``menu``, a separator where their section changes."""
        section = None
        for c in self.commands.in_menu(menu):
            if section is not None and c.section != section:
                self.dpg.add_separator()
            section = c.section
            self.dpg.add_menu_item(label=c.label, callback=self._on_command, user_data=c.id)

    def _on_command(self, sender, value, command_id):
        self.commands.run(command_id)

    def show_keys_help(self, *args) -> None:
        self.commands.run("show_info", "Keys and mouse", keys_help(self.commands))

    def _on_layout(self, sender, value, name):
        self.commands.run("layout", name)

    def _on_show(self, sender, value, key):
        self.commands.run("show", key, bool(value))

    def sync_window_checks(self) -> None:
        dpg = self.dpg
        built = set(built_windows(dpg))
        for key in WINDOWS:
            if key not in built:       # a registered window this build has no panel for
                dpg.configure_item(f"menu_show_{key}", show=False)
                continue
            shown = bool(dpg.is_item_shown(window_tag(key)))
            if dpg.get_value(f"menu_show_{key}") != shown:
                dpg.set_value(f"menu_show_{key}", shown)

    def update(self, view: View) -> None:
        names = " + ".join(n.upper() for n in self.ctx.engine.controller_names())
        # the frame rate (a median of the last frames) 4 times a second, as the Stats panel's numbers
        if self._fps is None or not 0 <= view.frame - self._fps[0] < 15:
            self._fps = (view.frame, view.frame_times.fps() if view.frame_times is not None else float("nan"))
        fps = self._fps[1]
        parts = [names, view.mode, f"tick {view.tick_number}", f"input: {view.input_name or 'keyboard/gamepad'}",
                 f"layout: {view.layout}", f"{fps:.0f} fps"]
        if view.recording is not None:
            parts.append("REC")
        if view.problems.get("lmm"):
            parts.append("LMM off (see Nearest Neighbour panel)")
        note = hidden_note(view.hidden_windows)
        if note:
            parts.append(note)
        self.text.set("menu_status", "   |   ".join(parts))
        self.text.set("menu_behind", self.behind())
        fit = self.data_fit.status_text(self.ctx.tuning)   # follows the speed sliders
        self.text.set("menu_data_fit", fit + "   " if fit else "")
        if fit:
            self.text.set("menu_data_fit_lines", "\n\n".join(self.data_fit.warnings(self.ctx.tuning)))

    def state(self) -> dict:
        return {"status": self.text.get("menu_status", ""), "behind": self.text.get("menu_behind", ""),
                "data_fit": self.text.get("menu_data_fit", "").strip(),
                "data_fit_lines": self.text.get("menu_data_fit_lines", "") if self.text.get("menu_data_fit") else ""}
