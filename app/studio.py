"""The studio: a dearpygui window with a motion matching and a learned motion matching character
driven by the same input, every internal visible live, every tunable on a slider.

This module is the shell: start-up (engine, window, panels) and the frame loop, which reads top to
bottom as the data flow::

    collect the ticks stepped last frame -> events/callbacks (sliders write the tuning) -> input
        -> viewport (3D) from the displayed tick -> panels from the displayed tick
        -> hand the next tick's input to the controllers -> dearpygui draws the frame

Both controllers step on a worker thread while dearpygui draws (it releases the GIL), so the
controllers' time overlaps the drawing; a tick handed over in frame N is shown in frame N+1, and a
slider moved in frame N acts on that tick. Every panel and the 3D view show the same displayed tick
(:mod:`app.playback`). The simulation is :class:`app.session.Session`; the look :mod:`app.theme`;
layouts :mod:`app.layouts` (fitted to the window by :mod:`app.window_fit`); file dialogs :mod:`app.dialogs`;
every user action a command of :mod:`app.studio_commands` (those on the simulation in :mod:`app.actions`);
test scripts :mod:`app.scripting`, the frame loop's observer (the test dump) :mod:`app.state_dump`.
"""
from __future__ import annotations

import signal
import sys
import time
from pathlib import Path

import numpy as np

from lmm.controller import InputState

from . import layout_files
from .actions import SessionActions
from .command_registry import CommandRegistry
from .dialogs import FileDialogs
from .frame_times import FrameTimes, per_tick_ms
from .input.keyboard import SHORTCUT_KEYS, shortcut_modifiers
from .layouts import LayoutManager
from .panels.base import EngineFacts, PanelContext, RecordingStatus, View
from .panels.common import window_alias, window_tag
from .panels.errors import ErrorDialog
from .playback import Playback
from .scripting import Screenshots, Script
from .state_dump import FrameObserver, StateDump, final_state, panel_state
from .studio_commands import register_studio_commands
from .engine import StudioOptions, load_session
from .prepared import Preparer
from .realtime import RealTimeRatio
from .tick_worker import TickWorker
from .theme import OPAQUE, WINDOW_BG, Theme

START_AZIMUTH = float(np.radians(35.0) + np.pi)     # the camera's start azimuth (input convention)
# item types that take typed text (a slider does after Ctrl+click): while one is being edited the
# keys belong to it, not to the characters or the shortcuts
TEXT_ENTRY_TYPES = {"mvInputText", "mvInputFloat", "mvInputInt", "mvInputDouble", "mvSliderFloat", "mvSliderInt",
                    "mvSliderDouble", "mvDragFloat", "mvDragInt", "mvDragDouble", "mvCombo"}


class Studio(SessionActions):
    def __init__(self, options: StudioOptions):
        import dearpygui.dearpygui as dpg

        self.dpg = dpg
        self.opts = options
        self.errors = ErrorDialog(dpg)
        self.theme = Theme(dpg)
        self.layouts = LayoutManager(dpg, self.errors.show, (options.width, options.height))
        self.frame_times = FrameTimes()
        self.realtime = RealTimeRatio()      # simulated over wall time: the menu bar says when behind
        self.frame_index = 0
        self.ui_antialiasing = True      # dearpygui's anti-aliased lines and fills (see _apply_ui_antialiasing)
        self.running = True
        self.exit_code = 0
        self.script = Script.load(options.script) if options.script else Script([])
        self.observer = StateDump(options.dump_state) if options.dump_state else FrameObserver()
        self.commands = register_studio_commands(CommandRegistry(), self)
        self.fixed_step = bool(options.fixed_step or options.frames is not None or options.script)
        self.input = None
        self._last_time = None
        self.screenshots = Screenshots(dpg)
        self._text_items, self._hidden = [], ()     # items that take text; windows hidden (names)

    # -- start-up ------------------------------------------------------------------------------
    def load_engine(self) -> None:
        self.session, self.lmm_problem = load_session(self.opts, self.errors.show)
        self.playback = Playback(self.session.history, self.session.dt, self.fixed_step)
        self.worker = TickWorker(self.session)
        if self.opts.input:
            self.open_input(self.opts.input)
        if self.opts.open:
            self.open_session_file(self.opts.open)

    def panel_context(self) -> PanelContext:
        s = self.session
        caps = [c.capabilities() for c in s.controllers.values()]
        engine = EngineFacts(db=s.db, features=s.features, dt=s.dt,
                             latent_dims=next((c.latent_dims for c in caps if c.latent_dims), 32),
                             controller_names=lambda: s.names, memory=lambda: s.memory,
                             features_of=lambda n: getattr(s.controllers.get(n), "features", None) or s.features,
                             manifest=self._manifest(), quality_text=s.quality.text)
        return PanelContext(dpg=self.dpg, tuning=s.tuning, commands=self.commands, theme=self.theme, engine=engine)

    def _manifest(self):
        """The manifest the database was built from (None when it cannot be read: ranges are then named
        by their takes' stems)."""
        from lmm import DEFAULT_MANIFEST
        from lmm.data.manifest import load_manifest

        try:
            return load_manifest(self.opts.manifest or DEFAULT_MANIFEST)
        except Exception:
            return None

    def build_ui(self) -> None:
        dpg = self.dpg
        from .panels.catalog import dock_panels
        from .panels.menu import MenuBar
        from .panels.viewport import ViewportPanel
        from .window_fit import WindowFit

        ini = self.layouts.choose(self.opts.layout)
        dpg.create_context()
        dpg.configure_app(docking=True, docking_space=False, manual_callback_management=True,
                          init_file=ini, load_init_file=True)
        self.theme.build()
        dpg.add_texture_registry(tag="texture_registry")
        with dpg.handler_registry(tag="studio_handlers"):
            dpg.add_mouse_wheel_handler(callback=lambda s, a: self.viewport.on_wheel(a))
        ctx = self.panel_context()
        self.menu = MenuBar(ctx)
        self.viewport = ViewportPanel(ctx, samples=self.opts.samples,
                                      render_scale=float(min(max(self.opts.render_scale, 0.25), 1.0)),
                                      readback=self.opts.readback_3d)
        self.panels = {"viewport": self.viewport}
        for cls in dock_panels():
            self.panels[cls.key] = cls(ctx)
        self.preparer = Preparer(self.panels)
        self.window_fit = WindowFit(dpg)
        self.menu.build()
        self.menu.behind = lambda: self.realtime.note(self.fixed_step)
        for key, panel in self.panels.items():
            panel.build(self.layouts.window_kwargs(key))
            if not dpg.does_alias_exist(window_alias(key)):
                dpg.add_alias(window_alias(key), window_tag(key))
        self.errors.build()
        dpg.bind_item_theme(self.errors.window, OPAQUE)
        self.dialogs = FileDialogs(dpg, {
            "input": self.open_input, "reference": self.open_reference, "preset_load": self.load_preset,
            "preset_save": self.save_preset, "weights": self.load_weights, "layout_load": self.switch_layout,
            "layout_save": self.layouts.save, "record": self.panels["recording"].set_path,
            "session": self.open_session_file},
            report_error=self.errors.show, confirm=self.errors.ask)
        self.dialogs.build()
        self._text_items = [i for i in dpg.get_all_items()
                            if dpg.get_item_type(i).rsplit("::", 1)[-1] in TEXT_ENTRY_TYPES]
        dpg.create_viewport(title="lmm-studio", width=self.opts.width, height=self.opts.height,
                            vsync=False, clear_color=WINDOW_BG)
        dpg.setup_dearpygui()
        dpg.show_viewport()
        self._init_input()

    def _init_input(self) -> None:
        from .input.keyboard import KeyboardInput, build_key_lookup

        dpg = self.dpg
        self.keyboard = KeyboardInput()
        self.key_lookup = build_key_lookup(lambda c: getattr(dpg, c, None))
        # (key code, (ctrl, shift) a chord needs or None, command id) of the commands that declare a shortcut
        self._shortcut_keys = [(getattr(dpg, SHORTCUT_KEYS[key]), shortcut_modifiers(key), c.id)
                               for key, c in self.commands.shortcuts().items()]
        try:
            from .input.manager import InputManager

            self.input = InputManager(self.keyboard, glfw_module="auto" if self.opts.gamepads else None,
                                      hid_module="auto" if self.opts.gamepads else None,
                                      camera_azimuth=START_AZIMUTH)
        except Exception as e:  # the input layer must never stop the studio
            self.input = None
            print(f"lmm-studio: gamepad input unavailable: {e}", file=sys.stderr)

    def gamepad_names(self) -> list[str]:
        if self.input is None:
            return []
        return [d.name for d in self.input.devices if d.kind != "keyboard"]

    # -- the frame -----------------------------------------------------------------------------
    def typing(self) -> bool:
        """Keys are text: a text field (or a slider in text mode) is edited or a file dialog is open."""
        return any(self.dpg.is_item_active(i) for i in self._text_items) or self.dialogs.visible

    def _keys(self) -> None:
        dpg = self.dpg
        names = set(self.script.keys)
        down = [name for code, name in self.key_lookup.items() if dpg.is_key_down(code)]
        held = ("ctrl" in down, "shift" in down)
        pressed = [c for key, mods, c in self._shortcut_keys if dpg.is_key_pressed(key) and mods in (None, held)]
        # typing() asks every text item whether it is being edited: only worth it when a key is down
        if (down or pressed) and not self.typing():
            names.update(down)
            for command in pressed:
                self.commands.run(command)
        self.keyboard.set_keys(names)

    def _live_input(self, frame_dt: float) -> InputState:
        if self.input is not None:
            return self.input.poll(frame_dt)
        kb = self.keyboard    # no input layer: keyboard only, the camera stays where it started
        (lx, ly), (rx, ry) = kb.left_stick(), kb.right_stick()
        return InputState(lx, ly, rx, ry, kb.walk, kb.strafe, START_AZIMUTH)

    def view(self, live: InputState) -> View:
        s, p = self.session, self.playback
        rec = s.recording
        replay = ""
        if s.input_log is not None:
            done = " (finished: last row holds)" if s.replay_finished() else ""
            replay = f"replaying {s.input_log.name}: {s.replay_time():.1f} / {s.input_log.duration:.1f} s{done}"
        return View(tick=p.displayed_tick(), history=s.history, live=p.live, paused=p.paused,
                    inspected=self.inspected, frame=self.frame_index,
                    problems={"lmm": self.lmm_problem} if self.lmm_problem else {},
                    latent_status=s.latent_table_status, frame_times=self.frame_times,
                    render_info=self.viewport.render_info() + ("" if self.ui_antialiasing else "; UI lines aliased"),
                    camera_azimuth=float(live.camera_azimuth),
                    recording=None if rec is None else RecordingStatus(
                        rec.frames * s.dt, tuple(Path(f).name for f in rec.paths.values())),
                    last_recording=self.last_recording, input_name=s.input_log.name if s.input_log else "",
                    replay_line=replay, devices=tuple(self.gamepad_names()),
                    reference=getattr(s.reference, "name", ""), layout=self.layouts.name,
                    following=s.following.name if s.following is not None else "",
                    hidden_windows=self._hidden, physics_status=s.physics_status,
                    ragdoll={} if s.ragdolls is None else {"enabled": s.ragdolls.enabled,
                                                           "residual": s.ragdolls.settings.residual,
                                                           "drawn": s.ragdolls.drawn})

    def frame(self) -> None:
        dpg = self.dpg
        t0 = time.perf_counter()
        frame_dt = 0.0 if self._last_time is None else t0 - self._last_time
        self._last_time = t0
        # the ticks stepped on the worker while the previous frame was drawn
        try:
            finished = self.worker.wait()
        except Exception as e:  # a controller failed: say so, stop simulating, keep the studio up
            import traceback

            traceback.print_exc()
            self.errors.show("Simulation", f"a controller failed and the simulation is paused: "
                                           f"{type(e).__name__}: {e}")
            self.playback.pause()
            finished = []
        if self.session.recording_error:     # a write failed (full disk): the recording stopped itself
            self.stop_recording()
            self.errors.show("Recording", self.last_recording)
        replaced = self.preparer.receive(self.worker.take_prepared())   # freed on the worker (submit)
        step_ms = per_tick_ms(finished, self.session.names)
        self.observer.ticks_finished(finished)
        # events and actions may change the session now: the worker is idle until submit()
        queue = dpg.get_callback_queue()
        if queue or self.frame_index % 10 == 0:
            self.layouts.forget_shown()     # a callback may show or hide a window; the x button is seen here
        dpg.run_callbacks(queue)
        self.errors.keep_shown()
        self.script.run(self.commands, self.frame_index)
        self._keys()
        self.session.undo.end_frame(self.dpg.is_mouse_button_down(0))   # this frame's changes: one step
        live = self._live_input(self.session.dt if self.fixed_step else frame_dt)
        n = self.playback.ticks_due(frame_dt)
        self.realtime.add(frame_dt, n * self.session.dt, self.playback.live and not self.playback.paused)
        inputs = [self.session.input_for_next_tick(live, ahead=k) for k in range(n)]
        self.observer.ticks_due(self.session, n)
        t1 = time.perf_counter()
        view = self.view(live)
        prep = self.preparer
        self.viewport.update(view, prep.result("viewport", view))
        t2 = time.perf_counter()
        shown = {"viewport"}
        for key, panel in self.panels.items():
            if key != "viewport" and self.layouts.shown(key):
                shown.add(key)
                if key in prep.panels:
                    panel.update(view, prep.result(key, view))
                else:
                    panel.update(view)
        self.menu.update(view)
        if self.frame_index % 10 == 0:
            self.theme.backgrounds()
            self.menu.sync_window_checks()   # a window closed with its own x button
            self.window_fit.check()          # the window was resized: the panels follow
            self._hidden = tuple(self.layouts.hidden())
        t3 = time.perf_counter()
        if not self.dialogs.visible:    # a file dialog covers the 3D view: faster frames catch its double-clicks
            self.viewport.render()      # the 3D view, once the panels are done (see there)
            self.viewport.finish()      # and its pixels in dearpygui's texture
        t_read = time.perf_counter()
        self.observer.frame_shown(self.frame_index, view, self.session, n, self.viewport.drawn.get("roots", {}))
        for label in self.script.captures:
            self.capture(label)
        self.script.captures.clear()
        # the next ticks are stepped on the worker while dearpygui draws (it releases the GIL);
        # from here to the next wait() nothing may touch the session
        self.worker.submit(inputs, prep.job(view, shown, self.frame_index + 1), release=replaced)
        replaced = None
        dpg.render_dearpygui_frame()
        t4 = time.perf_counter()
        # the observer's own work (a test and benchmark instrument) is not the studio's
        parts = {"input": (t1 - t0 - self.observer.spent_s()) * 1e3, "viewport": (t2 - t1) * 1e3,
                 "render": self.viewport.render_ms, "readback": self.viewport.readback_ms,
                 "panels": (t3 - t2) * 1e3, "ui": (t4 - t_read) * 1e3}
        parts.update(step_ms)   # per-tick controller time of the ticks finished for this frame (in parallel)
        self.observer.frame_timed((t4 - t0) * 1e3, parts)
        self.frame_times.add((t4 - t0) * 1e3, parts)
        self.frame_index += 1

    # -- run -----------------------------------------------------------------------------------
    def run(self) -> int:
        dpg = self.dpg
        # Ctrl-C / kill: leave the frame loop and shut down normally (the layout is saved)
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                signal.signal(sig, lambda *_: self.quit())
            except (ValueError, OSError):  # not the main thread
                pass
        self.load_engine()
        self.build_ui()
        dpg.render_dearpygui_frame()          # dearpygui's GL context exists after the first frame
        try:
            self.viewport.init_gl()
        except Exception as e:
            self.errors.show("3D view", f"cannot share dearpygui's OpenGL context: {e}")
        self._apply_ui_antialiasing()
        self.layouts.settle()
        self.menu.sync_window_checks()
        self._hidden = tuple(self.layouts.hidden())
        if self.opts.write_layouts:
            return self._write_layouts(self.opts.write_layouts)
        try:
            while self.running and dpg.is_dearpygui_running():
                last = self.opts.frames is not None and self.frame_index >= self.opts.frames - 1
                if last and self.opts.screenshot:
                    self.request_screenshot(self.opts.screenshot)
                self.frame()
                if self.frame_index >= 3:
                    self.layouts.started()    # the start layout works: no crash-loop guard needed
                if self.opts.frames is not None and self.frame_index >= self.opts.frames:
                    break
            self.layouts.started()
            self.exit_code = max(self.exit_code, self.screenshots.finish(self.errors.show))
        finally:
            self.shutdown()
        return self.exit_code

    def request_screenshot(self, path: str) -> Path:
        return self.screenshots.request(path)

    def _write_layouts(self, folder: str) -> int:
        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        for name in layout_files.builtin_names():
            self.layouts.apply(layout_files.from_builtin(name))
            for _ in range(4):
                self.frame()
            self.layouts.save(str(out / f"{name}.ini"))
            print(f"wrote {out / f'{name}.ini'}")
        self.opts.save_layout = False
        self.shutdown()
        return 0

    def shutdown(self) -> None:
        dpg = self.dpg
        if getattr(self, "worker", None) is not None:
            try:
                self.observer.ticks_finished(self.worker.wait())     # the ticks stepped during the last frame
            finally:
                self.worker.close()
        if getattr(self, "session", None) is not None and self.session.recording is not None:
            self.stop_recording()
        if self.opts.save_layout and dpg.is_dearpygui_running():
            try:
                self.layouts.save(str(layout_files.user_layout_path()))
            except Exception as e:
                print(f"lmm-studio: could not save the layout: {e}", file=sys.stderr)
        self.observer.finish(lambda: final_state(self))
        if self.input is not None:
            self.input.close()
        dpg.destroy_context()
        self.layouts.close()

    def _apply_ui_antialiasing(self) -> None:
        """dearpygui's anti-aliased lines and fills (``--ui-antialiasing``): "auto" turns them off where GL
        rasterises on the CPU (11 % of dearpygui's frame there), on otherwise; the Stats panel says so."""
        choice = self.opts.ui_antialiasing
        on = choice == "on" or (choice == "auto" and not self.viewport.software_gl())
        self.dpg.configure_app(anti_aliased_lines=on, anti_aliased_lines_use_tex=on, anti_aliased_fill=on)
        self.ui_antialiasing = on

    def capture(self, label: str) -> None:
        """Record what every panel shows now under ``label`` (test scripts)."""
        self.observer.capture(label, self.frame_index, self.playback.displayed_tick(), lambda: panel_state(self))


def run_studio(options: StudioOptions) -> int:
    return Studio(options).run()
