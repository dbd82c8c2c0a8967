"""Recording & input: record MM, LMM or both to BVH together with the input CSV; replay an input CSV
(or a built-in scenario) into the studio; see which input devices drive the characters."""
from __future__ import annotations

from .common import TextCache, window_tag

BUILTINS = ("circle", "zigzag", "stop-and-go", "strafe", "turns", "random:1")


class RecordingPanel:
    def __init__(self, dpg, studio):
        self.dpg = dpg
        self.studio = studio
        self.tag = window_tag("recording")
        self.text = TextCache(dpg)
        self.last_written: dict = {}

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        names = self.studio.session.names
        with dpg.window(tag=self.tag, label="Recording & Input", **window_kwargs):
            dpg.add_text("Record to BVH (+ input CSV)", color=(200, 200, 210))
            with dpg.group(horizontal=True):
                dpg.add_checkbox(label="MM", tag="rec_mm", default_value=True)
                dpg.add_checkbox(label="LMM", tag="rec_lmm", default_value="lmm" in names, enabled="lmm" in names)
            with dpg.group(horizontal=True):
                dpg.add_input_text(tag="rec_path", default_value=str(self.studio.default_recording_path()),
                                   width=-70)
                dpg.add_button(label="Browse", callback=lambda: self.studio.open_dialog("record"))
            with dpg.group(horizontal=True):
                dpg.add_button(label="Record", tag="rec_button", width=90, callback=self._on_record)
                dpg.add_text("", tag="rec_status", wrap=0)
            dpg.add_separator()
            dpg.add_text("Input", color=(200, 200, 210))
            dpg.add_text("", tag="inp_status", wrap=0)
            with dpg.group(horizontal=True):
                dpg.add_button(label="Replay CSV...", callback=lambda: self.studio.open_dialog("input"))
                dpg.add_combo(BUILTINS, tag="inp_builtin", default_value="circle", width=100)
                dpg.add_button(label="Play", callback=lambda: self.studio.open_input(
                    "builtin:" + dpg.get_value("inp_builtin")))
            with dpg.group(horizontal=True):
                dpg.add_button(label="Live input", callback=lambda: self.studio.live_input())
                dpg.add_button(label="Reset characters", callback=lambda: self.studio.reset_characters())
            dpg.add_text("", tag="inp_devices", color=(150, 150, 160), wrap=0)
            dpg.add_separator()
            with dpg.group(horizontal=True):
                dpg.add_button(label="Reference BVH...", callback=lambda: self.studio.open_dialog("reference"))
                dpg.add_text("", tag="ref_status")

    def which(self) -> tuple[str, ...]:
        dpg = self.dpg
        return tuple(n for n in ("mm", "lmm") if dpg.get_value(f"rec_{n}") and n in self.studio.session.names)

    def _on_record(self, *args):
        if self.studio.session.recording is not None:
            self.studio.stop_recording()
        else:
            self.studio.start_recording(self.dpg.get_value("rec_path"), self.which())

    def update(self, view) -> None:
        dpg = self.dpg
        s = self.studio.session
        if view.frame % 30 == 0:   # LMM may have been loaded since (File > Load LMM weights)
            dpg.configure_item("rec_lmm", enabled="lmm" in s.controllers)
        rec = s.recording
        if rec is not None:
            dpg.configure_item("rec_button", label="Stop")
            files = ", ".join(p.name for p in rec.paths.values())
            self.text.set("rec_status", f"REC {rec.frames * s.dt:5.1f} s -> {files}")
        else:
            dpg.configure_item("rec_button", label="Record")
            if self.last_written:
                self.text.set("rec_status", "wrote " + ", ".join(p.name for p in self.last_written.values()))
        if s.input_log is not None:
            done = " (finished: last row holds)" if s.replay_finished() else ""
            self.text.set("inp_status", f"replaying {s.input_log.name}: {s.replay_time():.1f} / "
                                        f"{s.input_log.duration:.1f} s{done}")
        else:
            self.text.set("inp_status", "live: keyboard (WASD/arrows, Shift walk, Ctrl strafe, Q/E camera)"
                                        + (" + gamepad" if self.studio.gamepad_names() else ""))
        pads = self.studio.gamepad_names()
        self.text.set("inp_devices", "gamepads: " + (", ".join(pads) if pads else "none connected"))
        ref = self.studio.viewport.reference
        self.text.set("ref_status", ref.name if ref is not None else "none")

    def state(self) -> dict:
        s = self.studio.session
        return {"recording": s.recording is not None,
                "last_written": {k: str(v) for k, v in self.last_written.items()},
                "input": None if s.input_log is None else s.input_log.name}
