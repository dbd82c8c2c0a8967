"""Recording & input: record MM, LMM or both to BVH together with the input CSV; replay an input CSV
(or a built-in scenario) into the studio; see which input devices drive the characters."""
from __future__ import annotations

from pathlib import Path

from .base import Panel, View

BUILTINS = ("circle", "zigzag", "stop-and-go", "strafe", "turns", "random:1")


def default_recording_path() -> Path:
    return Path.cwd() / "recordings" / "take.bvh"


class RecordingPanel(Panel):
    key = "recording"
    _recording = False

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        act = self.ctx.actions
        names = self.ctx.engine.controller_names()
        with self.window(window_kwargs):
            dpg.add_text("Record to BVH (+ input CSV)", color=(200, 200, 210))
            with dpg.group(horizontal=True):
                dpg.add_checkbox(label="MM", tag="rec_mm", default_value=True)
                dpg.add_checkbox(label="LMM", tag="rec_lmm", default_value="lmm" in names, enabled="lmm" in names)
            with dpg.group(horizontal=True):
                dpg.add_input_text(tag="rec_path", default_value=str(default_recording_path()), width=-70)
                dpg.add_button(label="Browse", callback=lambda: act.open_dialog("record"))
            with dpg.group(horizontal=True):
                dpg.add_button(label="Record", tag="rec_button", width=90, callback=self._on_record)
                dpg.add_text("", tag="rec_status", wrap=0)
            dpg.add_separator()
            dpg.add_text("Input", color=(200, 200, 210))
            dpg.add_text("", tag="inp_status", wrap=0)
            with dpg.group(horizontal=True):
                dpg.add_button(label="Replay CSV...", callback=lambda: act.open_dialog("input"))
                dpg.add_combo(BUILTINS, tag="inp_builtin", default_value="circle", width=100)
                dpg.add_button(label="Play", callback=lambda: act.open_input("builtin:" + dpg.get_value("inp_builtin")))
            with dpg.group(horizontal=True):
                dpg.add_button(label="Live input", callback=lambda: act.live_input())
                dpg.add_button(label="Reset characters", callback=lambda: act.reset_characters())
            dpg.add_text("", tag="inp_devices", color=(150, 150, 160), wrap=0)
            dpg.add_separator()
            with dpg.group(horizontal=True):
                dpg.add_button(label="Reference BVH...", callback=lambda: act.open_dialog("reference"))
                dpg.add_text("", tag="ref_status")

    def path(self) -> str:
        return self.dpg.get_value("rec_path")

    def set_path(self, path: str) -> None:
        self.dpg.set_value("rec_path", str(path))

    def which(self) -> tuple[str, ...]:
        names = self.ctx.engine.controller_names()
        return tuple(n for n in ("mm", "lmm") if self.dpg.get_value(f"rec_{n}") and n in names)

    def _on_record(self, *args):
        if self._recording:
            self.ctx.actions.stop_recording()
        else:
            self.ctx.actions.start_recording(self.path(), self.which())

    def update(self, view: View) -> None:
        dpg = self.dpg
        if view.frame % 30 == 0:   # LMM may have been loaded since (File > Load LMM weights)
            dpg.configure_item("rec_lmm", enabled="lmm" in self.ctx.engine.controller_names())
        rec = view.recording
        self._recording = rec is not None
        dpg.configure_item("rec_button", label="Stop" if rec is not None else "Record")
        if rec is not None:
            self.text.set("rec_status", f"REC {rec.seconds:5.1f} s -> {', '.join(rec.files)}")
        else:
            self.text.set("rec_status", view.last_recording)
        keyboard = "live: keyboard (WASD/arrows, Shift walk, Ctrl strafe, Q/E camera)"
        self.text.set("inp_status", view.replay_line or keyboard + (" + gamepad" if view.devices else ""))
        self.text.set("inp_devices", "gamepads: " + (", ".join(view.devices) if view.devices else "none connected"))
        self.text.set("ref_status", view.reference or "none")
        self.last = {"recording": rec is not None, "status": self.text.get("rec_status", ""),
                     "input": view.input_name or None}
