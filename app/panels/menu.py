"""The menu bar: files (input, reference BVH, presets, weights), layouts, window visibility, help,
and a status line (mode, fps, tick, last error)."""
from __future__ import annotations

from .common import WINDOWS, TextCache, window_tag
from .layouts import builtin_names

KEYS_HELP = """Keyboard (the 3D view does not need focus; text fields do take the keys):
  W A S D / arrows   move (camera relative)      Shift  walk        Ctrl  strafe
  I J K L            aim (right stick)           Q / E  turn the camera
  Space              pause / play                , .    step back / forward (paused)
  Home               back to live                F      toggle camera follow
Mouse on the 3D view: left-drag orbit, right/middle-drag pan, wheel zoom.
Gamepads (glfw or raw HID): left stick move, right stick aim/camera, LB walk, RB strafe."""


class MenuBar:
    def __init__(self, dpg, studio):
        self.dpg = dpg
        self.studio = studio
        self.text = TextCache(dpg)

    def build(self) -> None:
        dpg = self.dpg
        s = self.studio
        with dpg.viewport_menu_bar(tag="menu_bar"):
            with dpg.menu(label="File"):
                dpg.add_menu_item(label="Replay input CSV...", callback=lambda: s.open_dialog("input"))
                dpg.add_menu_item(label="Open reference BVH...", callback=lambda: s.open_dialog("reference"))
                dpg.add_separator()
                dpg.add_menu_item(label="Load tuning preset...", callback=lambda: s.open_dialog("preset_load"))
                dpg.add_menu_item(label="Save tuning preset...", callback=lambda: s.open_dialog("preset_save"))
                dpg.add_menu_item(label="Load LMM weights...", callback=lambda: s.open_dialog("weights"))
                dpg.add_separator()
                dpg.add_menu_item(label="Reset characters", callback=lambda: s.reset_characters())
                dpg.add_menu_item(label="Quit", callback=lambda: s.quit())
            with dpg.menu(label="Layout"):
                for name in builtin_names():
                    dpg.add_menu_item(label=name.capitalize(), callback=self._on_layout, user_data=name,
                                      tag=f"menu_layout_{name}")
                dpg.add_separator()
                dpg.add_menu_item(label="Load layout file...", callback=lambda: s.open_dialog("layout_load"))
                dpg.add_menu_item(label="Save layout as...", callback=lambda: s.open_dialog("layout_save"))
            with dpg.menu(label="Windows"):
                for key, (tag, title) in WINDOWS.items():
                    dpg.add_menu_item(label=title, check=True, default_value=True, tag=f"menu_show_{key}",
                                      callback=self._on_show, user_data=key)
            with dpg.menu(label="Help"):
                dpg.add_menu_item(label="Keys and mouse", callback=lambda: s.errors_info("Keys and mouse", KEYS_HELP))
            dpg.add_spacer(width=30)
            dpg.add_text("", tag="menu_status", color=(170, 200, 170))

    def _on_layout(self, sender, value, name):
        self.studio.switch_layout(name)

    def _on_show(self, sender, value, key):
        self.studio.show_window(key, bool(value))

    def sync_window_checks(self) -> None:
        dpg = self.dpg
        for key in WINDOWS:
            shown = bool(dpg.is_item_shown(window_tag(key)))
            if dpg.get_value(f"menu_show_{key}") != shown:
                dpg.set_value(f"menu_show_{key}", shown)

    def update(self, view) -> None:
        s = self.studio
        names = " + ".join(n.upper() for n in s.session.names)
        mode = "LIVE" if view.live else ("PAUSED" if view.paused else "REWIND")
        inp = s.session.input_log.name if s.session.input_log is not None else "keyboard/gamepad"
        status = f"{names}   |   {mode}   |   tick {view.tick_number}   |   input: {inp}   |   " \
                 f"layout: {s.layout_name}   |   {s.frame_times.fps():.0f} fps"
        if s.session.recording is not None:
            status += "   |   REC"
        if s.lmm_problem:
            status += "   |   LMM off (see Nearest Neighbour panel)"
        self.text.set("menu_status", status)
