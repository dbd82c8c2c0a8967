"""The studio: a dearpygui window with a motion matching and a learned motion matching character
driven by the same input, every internal visible live, every tunable on a slider.

The frame loop reads top to bottom as the data flow::

    collect the ticks stepped last frame -> events/callbacks (sliders write the tuning) -> input
        -> viewport (3D) from the displayed tick -> panels from the displayed tick
        -> hand the next tick's input to the controllers -> dearpygui draws the frame

Both controllers step on a worker thread while dearpygui draws (it releases the GIL), so the
controllers' time overlaps the drawing; a tick handed over in frame N is shown in frame N+1, and a
slider moved in frame N acts on that tick. "Displayed tick" is the newest tick when live, or the
scrubbed one while rewinding; every panel and the 3D view show the same tick. The simulation side
(controllers, the shared tuning, history, recording) lives in :class:`app.session.Session`; this
module owns only the GUI.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lmm.controller import InputState

from .panels import layouts as layout_files
from .panels.common import WINDOWS, View, window_alias, window_tag
from .panels.common import overlapping as overlap_keys
from .panels.errors import ErrorDialog
from .panels.stats import FrameTimes
from lmm.factory import make_controller, make_controllers

from .session import Session, TickWorker, load_reference_clip

FONT_CANDIDATES = (
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/noto/NotoSans-Regular.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    "C:/Windows/Fonts/segoeui.ttf",
    "/System/Library/Fonts/Supplemental/Arial.ttf",
    "/Library/Fonts/Arial.ttf",
)

WINDOW_BG = (30, 32, 38, 255)

DIALOGS = {
    # kind -> (title, extensions, default file name)
    "input": ("Replay input CSV", (".csv",), ""),
    "reference": ("Open reference BVH", (".bvh", ".gz"), ""),
    "preset_load": ("Load tuning preset", (".json",), ""),
    "preset_save": ("Save tuning preset", (".json",), "preset.json"),
    "weights": ("Load LMM weights", (".npz",), ""),
    "layout_load": ("Load layout", (".ini",), ""),
    "layout_save": ("Save layout as", (".ini",), "my_layout.ini"),
    "record": ("Record to", (".bvh",), "take.bvh"),
}


@dataclass
class StudioOptions:
    manifest: str | None = None
    weights: str | None = None
    layout: str | None = None
    input: str | None = None
    frames: int | None = None
    screenshot: str | None = None
    width: int = 1600
    height: int = 900
    lmm: bool = True
    script: str | None = None
    dump_state: str | None = None
    fixed_step: bool = False
    gamepads: bool = True
    save_layout: bool = True
    write_layouts: str | None = None
    samples: int = -1
    render_scale: float = 1.0
    cache: str | None = None


class Studio:
    def __init__(self, options: StudioOptions):
        import dearpygui.dearpygui as dpg

        self.dpg = dpg
        self.opts = options
        self.errors = ErrorDialog(dpg)
        self.frame_times = FrameTimes()
        self.frame_index = 0
        self.paused = False
        self.scrub_tick: int | None = None       # None: live
        self.pending_steps = 0
        self.inspected = "mm"
        self.lmm_problem: str | None = None
        self.layout_name = "default"
        self.layout = None
        self.running = True
        self.exit_code = 0
        self.script_keys: set[str] = set()
        self.script = _Script.load(options.script) if options.script else _Script([])
        self.dump = {"frames": [], "ticks": [], "labels": {}, "layout_switches": [], "recordings": []}
        self._submitted: dict[int, int] = {}          # tick -> frame whose inputs it was stepped with
        self._tuning_at_submit: dict[int, dict] = {}
        self.fixed_step = bool(options.fixed_step or options.frames is not None or options.script)
        self._acc = 0.0
        self._last_time = None
        self._working_ini = None
        self.input = None
        self._screenshots: list[Path] = []
        self.pending_captures: list[str] = []

    # ==========================================================================================
    # start-up
    # ==========================================================================================
    def load_engine(self) -> None:
        from lmm.data.database import load_or_build
        from lmm.features import build_features
        from lmm.tuning import Tuning

        try:
            db, _ = load_or_build(self.opts.manifest, cache_dir=self.opts.cache)
        except Exception as e:  # a broken manifest or BVH file: say so and open the default data
            if self.opts.manifest is None:
                raise
            self.errors.show("Database", f"{e} - opened the default database instead")
            self.opts.manifest = None
            db, _ = load_or_build(None, cache_dir=self.opts.cache)
        features = build_features(db)
        tuning = Tuning()
        controllers, problems = make_controllers(db, features, tuning, weights=self.opts.weights,
                                                 with_lmm=self.opts.lmm)
        for p, serious in problems:
            self.lmm_problem = p
            if serious:
                self.errors.show("Learned motion matching", p)
            else:
                print(f"lmm-studio: {p}", file=sys.stderr)
        if not self.opts.lmm:
            self.lmm_problem = "LMM is off (--no-lmm)"
        self.session = Session(db, features, tuning, controllers)
        self.worker = TickWorker(self.session)
        self.session.start_latent_table(self.opts.weights)
        if self.opts.input:
            self.open_input(self.opts.input)

    def _choose_layout(self):
        """(Layout, ini file to hand dearpygui or None)."""
        candidates = []
        if self.opts.layout:
            candidates.append(("--layout", self.opts.layout))
        elif layout_files.user_layout_path().is_file():
            candidates.append(("user", str(layout_files.user_layout_path())))
        candidates.append(("default", "default"))
        for origin, spec in candidates:
            try:
                layout = layout_files.load(spec)
                if origin == "user":
                    layout.name = "user"
                return layout, layout.path
            except layout_files.LayoutError as e:
                self.errors.show("Layout", f"{e} - using the default layout instead")
        return layout_files.from_builtin("default"), None

    def _prepare_ini(self, path) -> str:
        """dearpygui may write its init file back while running: give it a private copy, never the
        shipped or user layout itself."""
        d = Path(tempfile.mkdtemp(prefix="lmm-studio-"))
        work = d / "session.ini"
        if path is not None:
            text = Path(path).read_text(encoding="utf-8", errors="replace")
            work.write_text(layout_files.strip_extra_section(text), encoding="utf-8")
        else:
            work.write_text("", encoding="utf-8")
        self._working_ini = work
        return str(work)

    def build_ui(self) -> None:
        dpg = self.dpg
        from .panels.features import FeaturesPanel
        from .panels.latent import LatentPanel
        from .panels.menu import MenuBar
        from .panels.recording import RecordingPanel
        from .panels.search import CandidatesPanel, SearchPanel
        from .panels.stats import StatsPanel
        from .panels.timeline import TimelinePanel
        from .panels.tuning import TuningPanel
        from .panels.viewport import ViewportPanel

        layout, ini = self._choose_layout()
        self.layout = layout
        self.layout_name = layout.name
        dpg.create_context()
        dpg.configure_app(docking=True, docking_space=False, manual_callback_management=True,
                          init_file=self._prepare_ini(ini), load_init_file=True)
        self._setup_font_and_theme()
        dpg.add_texture_registry(tag="studio_textures")
        with dpg.handler_registry(tag="studio_handlers"):
            dpg.add_mouse_wheel_handler(callback=lambda s, a: self.viewport.on_wheel(a))
        self.menu = MenuBar(dpg, self)
        self.viewport = ViewportPanel(dpg, self)
        self.viewport.samples = self.opts.samples
        self.viewport.render_scale = float(min(max(self.opts.render_scale, 0.25), 1.0))
        self.panels = {
            "viewport": self.viewport,
            "features": FeaturesPanel(dpg, self),
            "latent": LatentPanel(dpg, self),
            "search": SearchPanel(dpg, self),
            "candidates": CandidatesPanel(dpg, self),
            "tuning": TuningPanel(dpg, self),
            "stats": StatsPanel(dpg, self),
            "timeline": TimelinePanel(dpg, self),
            "recording": RecordingPanel(dpg, self),
        }
        self.menu.build()
        code_layout = layout_files.from_builtin("default")
        for key, panel in self.panels.items():
            rect = layout.windows.get(key) or code_layout.windows.get(key) or {"pos": (40, 60), "size": (400, 300)}
            kwargs = dict(pos=rect["pos"] or (40, 60), width=(rect["size"] or (400, 300))[0],
                          height=(rect["size"] or (400, 300))[1], show=key not in layout.hidden,
                          no_collapse=False)
            panel.build(kwargs)
            dpg.add_alias(window_alias(key), window_tag(key)) if not dpg.does_alias_exist(window_alias(key)) else None
        self.errors.build()
        dpg.bind_item_theme(self.errors.window, "opaque_window")
        self._build_dialogs()
        dpg.create_viewport(title="lmm-studio", width=self.opts.width, height=self.opts.height,
                            vsync=False, clear_color=WINDOW_BG)
        dpg.setup_dearpygui()
        dpg.show_viewport()
        self._init_input()

    def _setup_font_and_theme(self) -> None:
        dpg = self.dpg
        font_path = next((p for p in FONT_CANDIDATES if os.path.isfile(p)), None)
        if font_path:
            with dpg.font_registry():
                font = dpg.add_font(font_path, 15)
            dpg.bind_font(font)
        with dpg.theme(tag="studio_theme"):
            with dpg.theme_component(dpg.mvAll):
                dpg.add_theme_style(dpg.mvStyleVar_WindowPadding, 8, 6)
                dpg.add_theme_style(dpg.mvStyleVar_FramePadding, 5, 3)
                dpg.add_theme_style(dpg.mvStyleVar_ItemSpacing, 6, 4)
                dpg.add_theme_style(dpg.mvStyleVar_FrameRounding, 3)
                dpg.add_theme_style(dpg.mvStyleVar_WindowRounding, 2)
                dpg.add_theme_style(dpg.mvStyleVar_GrabRounding, 3)
                # panels tile the window over a clear colour of the same grey, so their own background
                # need not be drawn (on software GL that fill costs ~12 ms a frame at 1600x900);
                # windows that overlap another get an opaque background (see _window_backgrounds)
                dpg.add_theme_color(dpg.mvThemeCol_WindowBg, WINDOW_BG[:3] + (0,))
                dpg.add_theme_color(dpg.mvThemeCol_TitleBg, (38, 40, 48, 255))
                dpg.add_theme_color(dpg.mvThemeCol_TitleBgActive, (52, 58, 78, 255))
                dpg.add_theme_color(dpg.mvThemeCol_FrameBg, (44, 47, 56, 255))
                dpg.add_theme_color(dpg.mvThemeCol_Header, (52, 58, 78, 255))
                dpg.add_theme_color(dpg.mvThemeCol_SliderGrab, (110, 150, 220, 255))
                dpg.add_theme_color(dpg.mvThemeCol_Button, (56, 62, 82, 255))
                dpg.add_theme_color(dpg.mvThemeCol_MenuBarBg, (36, 38, 46, 255))
                dpg.add_theme_color(dpg.mvPlotCol_PlotBg, (0, 0, 0, 0), category=dpg.mvThemeCat_Plots)
                dpg.add_theme_color(dpg.mvPlotCol_FrameBg, (30, 32, 38, 0), category=dpg.mvThemeCat_Plots)
                dpg.add_theme_style(dpg.mvPlotStyleVar_PlotPadding, 4, 4, category=dpg.mvThemeCat_Plots)
                dpg.add_theme_style(dpg.mvPlotStyleVar_LabelPadding, 2, 2, category=dpg.mvThemeCat_Plots)
                dpg.add_theme_style(dpg.mvPlotStyleVar_FillAlpha, 0.9, category=dpg.mvThemeCat_Plots)
        dpg.bind_theme("studio_theme")
        with dpg.theme(tag="opaque_window"):
            with dpg.theme_component(dpg.mvAll):
                dpg.add_theme_color(dpg.mvThemeCol_WindowBg, WINDOW_BG)
                dpg.add_theme_color(dpg.mvThemeCol_ChildBg, WINDOW_BG)
        self._series_themes = {}
        self._opaque: set[str] = set()

    def theme_series(self, item, color, weight: float | None = None, bar: bool = False, marker: bool = False) -> None:
        """Give a plot series a colour (and line weight / bar fill / marker)."""
        dpg = self.dpg
        key = (tuple(color), weight, bar, marker)
        theme = self._series_themes.get(key)
        if theme is None:
            rgba = tuple(int(round(c * 255)) for c in color[:3]) + (255,)
            with dpg.theme() as theme:
                with dpg.theme_component(dpg.mvAll):
                    dpg.add_theme_color(dpg.mvPlotCol_Line, rgba, category=dpg.mvThemeCat_Plots)
                    dpg.add_theme_color(dpg.mvPlotCol_Fill, rgba, category=dpg.mvThemeCat_Plots)
                    dpg.add_theme_color(dpg.mvPlotCol_MarkerFill, rgba, category=dpg.mvThemeCat_Plots)
                    dpg.add_theme_color(dpg.mvPlotCol_MarkerOutline, rgba, category=dpg.mvThemeCat_Plots)
                    if weight is not None:
                        dpg.add_theme_style(dpg.mvPlotStyleVar_LineWeight, weight, category=dpg.mvThemeCat_Plots)
                    if marker:
                        dpg.add_theme_style(dpg.mvPlotStyleVar_Marker, dpg.mvPlotMarker_Circle,
                                            category=dpg.mvThemeCat_Plots)
                        dpg.add_theme_style(dpg.mvPlotStyleVar_MarkerSize, 3.0, category=dpg.mvThemeCat_Plots)
            self._series_themes[key] = theme
        dpg.bind_item_theme(item, theme)

    def _build_dialogs(self) -> None:
        dpg = self.dpg
        for kind, (title, exts, default) in DIALOGS.items():
            with dpg.file_dialog(label=title, tag=f"dlg_{kind}", show=False, modal=True, width=700, height=420,
                                 callback=self._on_dialog, user_data=kind, default_filename=default,
                                 directory_selector=False):
                for ext in exts:
                    dpg.add_file_extension(ext, color=(180, 220, 140, 255))
                dpg.add_file_extension(".*")
            dpg.bind_item_theme(f"dlg_{kind}", "opaque_window")

    def _init_input(self) -> None:
        from .input.keyboard import KeyboardInput, build_key_lookup

        dpg = self.dpg
        self.keyboard = KeyboardInput()
        self.key_lookup = build_key_lookup(lambda c: getattr(dpg, c, None))
        try:
            from .input.manager import InputManager

            self.input = InputManager(self.keyboard, glfw_module="auto" if self.opts.gamepads else None,
                                      hid_module="auto" if self.opts.gamepads else None,
                                      camera_azimuth=float(np.radians(35.0) + np.pi))
        except Exception as e:  # the input layer must never stop the studio
            self.input = None
            print(f"lmm-studio: gamepad input unavailable: {e}", file=sys.stderr)

    # ==========================================================================================
    # actions (menu, panels and test scripts call these)
    # ==========================================================================================
    def open_dialog(self, kind: str) -> None:
        if kind == "record":
            p = Path(self.dpg.get_value("rec_path")).expanduser()
            self.dpg.configure_item("dlg_record", default_path=str(p.parent if p.parent.is_dir() else Path.cwd()))
        self.dpg.configure_item(f"dlg_{kind}", show=True)

    def _on_dialog(self, sender, app_data, kind):
        path = (app_data or {}).get("file_path_name") or ""
        if not path:
            return
        self.handle_file(kind, path)

    def handle_file(self, kind: str, path: str) -> None:
        handlers = {"input": self.open_input, "reference": self.open_reference, "preset_load": self.load_preset,
                    "preset_save": self.save_preset, "weights": self.load_weights,
                    "layout_load": self.switch_layout, "layout_save": self.save_layout,
                    "record": lambda p: self.dpg.set_value("rec_path", p)}
        handlers[kind](path)

    def open_input(self, spec: str) -> bool:
        from lmm.data.inputs import InputError, open_input

        try:
            log = open_input(spec)
        except (InputError, OSError, ValueError) as e:
            self.errors.show("Input", str(e))
            return False
        self.session.replay(log)
        self.go_live()
        return True

    def live_input(self) -> None:
        self.session.stop_replay()

    def reset_characters(self) -> None:
        self.session.reset()
        self.go_live()

    def open_reference(self, path: str) -> bool:
        from lmm.data.bvh import BVHError

        try:
            clip = load_reference_clip(path)
        except (BVHError, OSError, EOFError, ValueError) as e:
            self.errors.show("Reference BVH", str(e) if str(path) in str(e) else f"{path}: {e}")
            return False
        except Exception as e:
            self.errors.show("Reference BVH", f"{path}: cannot load: {type(e).__name__}: {e}")
            return False
        self.viewport.set_reference(clip)
        return True

    def load_preset(self, path: str) -> bool:
        from lmm.tuning import TuningError

        try:
            self.panels["tuning"].load_preset(path)
        except (TuningError, OSError, ValueError) as e:
            self.errors.show("Tuning preset", str(e) if str(path) in str(e) else f"{path}: {e}")
            return False
        return True

    def save_preset(self, path: str) -> bool:
        try:
            self.panels["tuning"].save_preset(path)
        except OSError as e:
            self.errors.show("Tuning preset", f"{path}: cannot write ({e.strerror})")
            return False
        return True

    def load_weights(self, path: str) -> bool:
        s = self.session
        try:
            controller = make_controller("lmm", s.db, s.features, s.tuning, weights=path)
        except Exception as e:
            self.errors.show("LMM weights", str(e) if str(path) in str(e) else f"{path}: {e}")
            return False
        s.controllers["lmm"] = controller
        self.lmm_problem = None
        s.start_latent_table(path)
        self.viewport.add_controller("lmm")
        self.reset_characters()
        return True

    def set_inspected(self, name: str) -> None:
        if name in self.session.controllers:
            self.inspected = name
            if self.dpg.does_item_exist("vp_inspect"):
                from .panels.common import SHORT

                self.dpg.set_value("vp_inspect", SHORT.get(name, name))

    # -- playback ------------------------------------------------------------------------------
    def toggle_pause(self) -> None:
        if self.paused:
            self.resume()
        else:
            self.pause()

    def pause(self) -> None:
        self.paused = True
        if self.scrub_tick is None and self.session.history.newest_tick >= 0:
            self.scrub_tick = self.session.history.newest_tick

    def resume(self) -> None:
        self.paused = False
        self.scrub_tick = None

    def go_live(self) -> None:
        self.scrub_tick = None
        self.paused = False

    def scrub_to(self, tick: int) -> None:
        h = self.session.history
        if h.newest_tick < 0:
            return
        self.paused = True
        self.scrub_tick = h.clamp(int(tick))

    def step(self, n: int) -> None:
        """Step the displayed tick by ``n``; stepping forward past the newest tick simulates new ticks."""
        h = self.session.history
        if not self.paused:
            self.pause()
        current = self.scrub_tick if self.scrub_tick is not None else h.newest_tick
        target = current + int(n)
        if target > h.newest_tick:
            self.pending_steps += target - h.newest_tick
            self.scrub_tick = None
        else:
            self.scrub_tick = h.clamp(target)

    def displayed_tick(self):
        h = self.session.history
        if self.scrub_tick is None:
            return h.latest()
        t = h.get(self.scrub_tick)
        if t is None:  # fell out of the buffer
            self.scrub_tick = h.clamp(self.scrub_tick)
            t = h.get(self.scrub_tick)
        return t

    # -- recording -----------------------------------------------------------------------------
    def default_recording_path(self) -> Path:
        return Path.cwd() / "recordings" / "take.bvh"

    def start_recording(self, path: str, which) -> bool:
        try:
            paths = self.session.start_recording(path, tuple(which))
        except (OSError, ValueError) as e:
            self.errors.show("Recording", f"{path}: {e}")
            return False
        self.dump["recordings"].append({"started": self.frame_index, "paths": {k: str(v) for k, v in paths.items()}})
        return True

    def stop_recording(self) -> dict:
        try:
            written = self.session.stop_recording()
        except Exception as e:
            self.errors.show("Recording", f"cannot finish the recording: {e}")
            return {}
        self.panels["recording"].last_written = written
        if self.dump["recordings"]:
            self.dump["recordings"][-1]["written"] = {k: str(v) for k, v in written.items()}
            self.dump["recordings"][-1]["stopped"] = self.frame_index
        return written

    # -- layouts -------------------------------------------------------------------------------
    def switch_layout(self, name_or_path: str) -> bool:
        try:
            layout = layout_files.load(name_or_path)
        except layout_files.LayoutError as e:
            self.errors.show("Layout", str(e))
            return False
        self.apply_layout(layout)
        self.dump["layout_switches"].append({"frame": self.frame_index, "layout": layout.name})
        return True

    def apply_layout(self, layout) -> None:
        dpg = self.dpg
        viewport = (dpg.get_viewport_client_width() or self.opts.width,
                    dpg.get_viewport_client_height() or self.opts.height)
        for key in WINDOWS:
            tag = window_tag(key)
            rect = layout.windows.get(key)
            show = key not in layout.hidden and rect is not None
            dpg.configure_item(tag, show=show)
            if rect is not None and rect.get("docked") and layout is self.layout and self.frame_index == 0:
                continue  # docked at start: dearpygui restored the dock node from the file already
            if rect is not None and rect.get("pos") is not None and rect.get("size") is not None:
                pos, size = layout_files.scaled(rect["pos"], rect["size"], layout.reference_size, viewport)
                dpg.set_item_pos(tag, pos)
                dpg.configure_item(tag, width=size[0], height=size[1])
        self.layout = layout
        self.layout_name = layout.name
        self.menu.sync_window_checks()

    def save_layout(self, path: str) -> bool:
        dpg = self.dpg
        try:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            dpg.save_init_file(str(path))
            hidden = [k for k in WINDOWS if not dpg.is_item_shown(window_tag(k))]
            text = layout_files.strip_extra_section(Path(path).read_text(encoding="utf-8"))
            text += layout_files.extra_section(hidden, (dpg.get_viewport_client_width() or self.opts.width,
                                                        dpg.get_viewport_client_height() or self.opts.height))
            Path(path).write_text(text, encoding="utf-8")
        except OSError as e:
            self.errors.show("Layout", f"{path}: cannot write ({e.strerror or e})")
            return False
        return True

    def show_window(self, key: str, show: bool) -> None:
        self.dpg.configure_item(window_tag(key), show=show)

    def errors_info(self, title: str, text: str) -> None:
        """Show a message in the dialog without counting it as an error."""
        self.errors.queue.append({"title": title, "message": text, "time": time.time()})
        self.errors._present()

    def quit(self) -> None:
        self.running = False

    def gamepad_names(self) -> list[str]:
        if self.input is None:
            return []
        return [d.name for d in self.input.devices if d.kind != "keyboard"]

    def _window_backgrounds(self) -> None:
        """Opaque background for panels that overlap another (dragged, floating), none for tiled ones."""
        dpg = self.dpg
        rects = {}
        for key in WINDOWS:
            tag = window_tag(key)
            if dpg.is_item_shown(tag):
                x, y = dpg.get_item_pos(tag)
                w, h = dpg.get_item_rect_size(tag)
                rects[key] = (x, y, x + w, y + h)
        overlapping = overlap_keys(rects)
        for key in set(WINDOWS):
            want = key in overlapping
            if want != (key in self._opaque):
                dpg.bind_item_theme(window_tag(key), "opaque_window" if want else 0)
                (self._opaque.add if want else self._opaque.discard)(key)

    # ==========================================================================================
    # the frame
    # ==========================================================================================
    def _keys(self, frame_dt: float) -> None:
        dpg = self.dpg
        typing = dpg.is_item_active("rec_path") or any(
            dpg.is_item_shown(f"dlg_{k}") for k in DIALOGS) or self.errors.visible
        names = set(self.script_keys)
        if not typing:
            for code, name in self.key_lookup.items():
                if dpg.is_key_down(code):
                    names.add(name)
            if dpg.is_key_pressed(dpg.mvKey_Spacebar):
                self.toggle_pause()
            if dpg.is_key_pressed(dpg.mvKey_Comma):
                self.step(-1)
            if dpg.is_key_pressed(dpg.mvKey_Period):
                self.step(1)
            if dpg.is_key_pressed(dpg.mvKey_Home):
                self.go_live()
            if dpg.is_key_pressed(dpg.mvKey_F):
                self.viewport.follow = not self.viewport.follow
                dpg.set_value("vp_follow", self.viewport.follow)
        self.keyboard.set_keys(names)

    def _live_input(self, frame_dt: float) -> InputState:
        if self.input is not None:
            state = self.input.poll(frame_dt)
        else:  # no input layer: keyboard only
            kb = self.keyboard
            (lx, ly), (rx, ry) = kb.left_stick(), kb.right_stick()
            state = InputState(lx, ly, rx, ry, kb.walk, kb.strafe, self.viewport.camera_azimuth())
        return state

    def _ticks_due(self, frame_dt: float) -> int:
        if self.paused:
            n, self.pending_steps = self.pending_steps, 0
            return n
        if self.fixed_step:
            return 1
        self._acc = min(self._acc + frame_dt, 0.25)
        n = int(self._acc / self.session.dt)
        self._acc -= n * self.session.dt
        return min(n, 4)

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
            self.pause()
            finished = []
        step_ms = dict.fromkeys(self.session.names, 0.0)
        for tick, ms in finished:
            for name in step_ms:
                step_ms[name] += ms.get(name, 0.0)
        if self.opts.dump_state:
            self._dump_ticks(finished)
        # events and actions may change the session now: the worker is idle until submit()
        dpg.run_callbacks(dpg.get_callback_queue())
        self.script.run(self, self.frame_index)
        self._keys(frame_dt)
        live = self._live_input(frame_dt if not self.fixed_step else self.session.dt)
        # the camera follows the input layer's azimuth (mouse orbit, Q/E, right stick feed it)
        if self.viewport.camera is not None and self.input is not None:
            self.viewport.camera.yaw_deg = float(np.degrees(self.input.camera_azimuth - np.pi)) % 360.0
        n = self._ticks_due(frame_dt)
        inputs = [self.session.input_for_next_tick(live, ahead=k) for k in range(n)]
        tuning_seen = self.session.tuning.to_dict() if self.opts.dump_state and n else None
        t1 = time.perf_counter()
        view = View(tick=self.displayed_tick(), live=self.scrub_tick is None and not self.paused,
                    paused=self.paused, inspected=self.inspected, history=self.session.history,
                    session=self.session, frame=self.frame_index)
        self.viewport.update(view)
        t3 = time.perf_counter()
        for key, panel in self.panels.items():
            if key != "viewport" and dpg.is_item_shown(panel.tag):
                panel.update(view)
        self.menu.update(view)
        if self.frame_index % 10 == 0:
            self._window_backgrounds()
            self.menu.sync_window_checks()   # a window closed with its own x button
        t4 = time.perf_counter()
        record = self._dump_frame(view, n, tuning_seen) if self.opts.dump_state else None
        for label in self.pending_captures:
            self.capture(label)
        self.pending_captures.clear()
        # the next ticks are stepped on the worker while dearpygui draws (it releases the GIL);
        # from here to the next wait() nothing may touch the session
        self.worker.submit(inputs)
        dpg.render_dearpygui_frame()
        t5 = time.perf_counter()
        vp = self.viewport
        parts = {"input": (t1 - t0) * 1e3, "viewport": (t3 - t1) * 1e3 - vp.render_ms - vp.readback_ms,
                 "render": vp.render_ms, "readback": vp.readback_ms, "panels": (t4 - t3) * 1e3,
                 "ui": (t5 - t4) * 1e3}
        parts.update(step_ms)          # controller time of the ticks finished for this frame (in parallel)
        self.frame_times.add((t5 - t0) * 1e3, parts)
        if record is not None:
            record.update({"ms": {k: round(float(v), 4) for k, v in parts.items()},
                           "frame_ms": round((t5 - t0) * 1e3, 4), "t": round(time.perf_counter(), 6),
                           "cpu": round(time.process_time(), 6)})
        self.frame_index += 1

    # ==========================================================================================
    # run
    # ==========================================================================================
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
        if self.layout is not None and self.layout.path is not None:
            vw = dpg.get_viewport_client_width() or self.opts.width
            vh = dpg.get_viewport_client_height() or self.opts.height
            if tuple(self.layout.reference_size) != (vw, vh):
                self.apply_layout(self.layout)
        elif self.layout is not None:
            self.apply_layout(self.layout)
        if self.opts.write_layouts:
            return self._write_layouts(self.opts.write_layouts)
        try:
            while self.running and dpg.is_dearpygui_running():
                last = self.opts.frames is not None and self.frame_index >= self.opts.frames - 1
                if last and self.opts.screenshot:
                    self.request_screenshot(self.opts.screenshot)
                self.frame()
                if self.opts.frames is not None and self.frame_index >= self.opts.frames:
                    break
            self._finish_screenshots()
        finally:
            self.shutdown()
        return self.exit_code

    def request_screenshot(self, path: str) -> Path:
        """Ask dearpygui to save the whole window during the next frame it renders."""
        out = Path(path)
        out.parent.mkdir(parents=True, exist_ok=True)
        if out.exists():
            out.unlink()
        self.dpg.output_frame_buffer(file=str(out))
        self._screenshots.append(out)
        return out

    def _finish_screenshots(self) -> None:
        """Render (without simulating) until every requested screenshot is on disk."""
        pending = [p for p in self._screenshots if not p.exists()]
        tries = 0
        while pending and tries < 5:
            self.dpg.render_dearpygui_frame()
            tries += 1
            pending = [p for p in pending if not p.exists()]
        for p in pending:
            self.errors.show("Screenshot", f"{p}: dearpygui did not write the screenshot")
            self.exit_code = 1

    def _write_layouts(self, folder: str) -> int:
        dpg = self.dpg
        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        for name in layout_files.builtin_names():
            self.apply_layout(layout_files.from_builtin(name))
            for _ in range(4):
                self.frame()
            self.save_layout(str(out / f"{name}.ini"))
            print(f"wrote {out / f'{name}.ini'}")
        self.opts.save_layout = False
        self.shutdown()
        return 0

    def shutdown(self) -> None:
        dpg = self.dpg
        if getattr(self, "worker", None) is not None:
            try:
                finished = self.worker.wait()     # the ticks stepped during the last frame
                if self.opts.dump_state:
                    self._dump_ticks(finished)
            finally:
                self.worker.close()
        if getattr(self, "session", None) is not None and self.session.recording is not None:
            self.stop_recording()
        if self.opts.save_layout and dpg.is_dearpygui_running():
            try:
                self.save_layout(str(layout_files.user_layout_path()))
            except Exception as e:
                print(f"lmm-studio: could not save the layout: {e}", file=sys.stderr)
        if self.opts.dump_state:
            self._write_dump()
        if self.input is not None:
            self.input.close()
        dpg.destroy_context()
        if self._working_ini is not None:
            shutil.rmtree(self._working_ini.parent, ignore_errors=True)

    # ==========================================================================================
    # test dump
    # ==========================================================================================
    def _dump_ticks(self, finished) -> None:
        for tick, _ in finished:
            self.dump["ticks"].append({
                "tick": tick.tick, "frame_submitted": self._submitted.get(tick.tick),
                "tuning_seen": self._tuning_at_submit.get(tick.tick),
                "roots": {n: [float(x) for x in s.pose.global_positions[0]] for n, s in tick.snapshots.items()},
                "desired_speed": {n: float(np.linalg.norm(s.desired_velocity)) for n, s in tick.snapshots.items()},
                "input": dict(vars(tick.extra["input"]))})

    def _dump_frame(self, view: View, ticks: int, tuning_seen) -> dict:
        latest = self.session.history.latest()
        first = self.session.tick + 1            # the ticks submitted this frame (still being stepped)
        for k in range(ticks):
            self._submitted[first + k] = self.frame_index
            self._tuning_at_submit[first + k] = tuning_seen
        rec = {"frame": self.frame_index, "ticks": ticks, "displayed_tick": view.tick_number,
               "newest_tick": self.session.history.newest_tick, "live": view.live,
               "roots": {n: [float(x) for x in s.pose.global_positions[0]] for n, s in latest.snapshots.items()}
               if latest is not None else {},
               "viewport_roots": self.viewport.drawn.get("roots", {})}
        self.dump["frames"].append(rec)
        return rec

    def panel_state(self) -> dict:
        out = {key: panel.state() for key, panel in self.panels.items()}
        out["windows"] = self.window_state()
        return out

    def window_state(self) -> dict:
        dpg = self.dpg
        return {key: {"pos": list(dpg.get_item_pos(window_tag(key))),
                      "size": [dpg.get_item_width(window_tag(key)), dpg.get_item_height(window_tag(key))],
                      "shown": bool(dpg.is_item_shown(window_tag(key)))} for key in WINDOWS}

    def capture(self, label: str) -> None:
        """Record what every panel shows now under ``label`` (test scripts)."""
        t = self.displayed_tick()
        self.dump["labels"][label] = {
            "frame": self.frame_index, "displayed_tick": -1 if t is None else t.tick,
            "snapshot_roots": {} if t is None else {n: [float(x) for x in s.pose.global_positions[0]]
                                                    for n, s in t.snapshots.items()},
            "snapshot_query": {} if t is None else {n: np.asarray(s.query).tolist() for n, s in t.snapshots.items()},
            "panels": self.panel_state()}

    def _write_dump(self) -> None:
        s = self.session
        self.dump.update({
            "frames_run": self.frame_index, "tick_count": s.tick, "controllers": s.names,
            "shared_tuning": all(getattr(c, "tuning", None) is s.tuning for c in s.controllers.values()),
            "lmm_problem": self.lmm_problem, "errors": list(self.errors.shown), "layout": self.layout_name,
            "final": self.panel_state(), "frame_times": {"median_ms": self.frame_times.median(),
                                                         "parts_ms": {k: self.frame_times.median(k)
                                                                      for k in self.frame_times.parts}},
            "user_layout": str(layout_files.user_layout_path()),
        })
        path = Path(self.opts.dump_state)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.dump, default=_json_default))


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    if isinstance(o, float):
        return None
    return str(o)


class _Script:
    """Timed test actions: ``[{"frame": 30, "do": "set_tuning", "field": ..., "value": ...}, ...]``.

    Actions: ``set_tuning`` (field, value[, channel]) sets the slider and fires its callback;
    ``key_down`` / ``key_up`` (key); ``record_start`` (path[, which]) / ``record_stop``; ``layout``
    (name or path); ``pause`` / ``resume`` / ``live`` / ``scrub`` (tick, or back: n ticks) / ``step`` (n);
    ``open`` (kind: input|reference|preset_load|preset_save|weights|layout_load|layout_save, path);
    ``inspect`` (controller); ``capture`` (label); ``screenshot`` (path); ``sort`` (key[, descending]);
    ``quit``; ``quit_when_exists`` (path: quit on the first frame that file exists).
    """

    def __init__(self, actions: list[dict]):
        self.actions = sorted(actions, key=lambda a: int(a.get("frame", 0)))
        self.i = 0
        self.quit_files: list[Path] = []

    @classmethod
    def load(cls, path) -> "_Script":
        data = json.loads(Path(path).read_text())
        return cls(data["actions"] if isinstance(data, dict) else data)

    def run(self, studio: Studio, frame: int) -> None:
        if any(p.exists() for p in self.quit_files):
            studio.quit()
        while self.i < len(self.actions) and int(self.actions[self.i].get("frame", 0)) <= frame:
            a = self.actions[self.i]
            self.i += 1
            self._do(studio, a)

    def _do(self, s: Studio, a: dict) -> None:
        do = a["do"]
        if do == "set_tuning":
            s.panels["tuning"].set_field(a["field"], a["value"], a.get("channel"))
        elif do == "key_down":
            s.script_keys.add(a["key"])
        elif do == "key_up":
            s.script_keys.discard(a["key"])
        elif do == "record_start":
            s.start_recording(a["path"], tuple(a.get("which", ("mm", "lmm"))))
        elif do == "record_stop":
            s.stop_recording()
        elif do == "layout":
            s.switch_layout(a["name"])
        elif do == "pause":
            s.pause()
        elif do == "resume":
            s.resume()
        elif do == "live":
            s.go_live()
        elif do == "scrub":
            s.scrub_to(a["tick"] if "tick" in a else s.session.history.newest_tick - int(a["back"]))
        elif do == "step":
            s.step(int(a.get("n", 1)))
        elif do == "open":
            s.handle_file(a["kind"], a["path"])
        elif do == "inspect":
            s.set_inspected(a["controller"])
        elif do == "capture":   # after this frame's panels updated: what they show for its tick
            s.pending_captures.append(a["label"])
        elif do == "screenshot":
            s.request_screenshot(a["path"])
        elif do == "sort":
            s.panels["candidates"].set_sort(a["key"], bool(a.get("descending", False)))
        elif do == "quit":
            s.quit()
        elif do == "quit_when_exists":  # external tests (real key presses) end the run by creating a file
            self.quit_files.append(Path(a["path"]))
        else:
            raise ValueError(f"unknown script action {do!r}")


def run_studio(options: StudioOptions) -> int:
    return Studio(options).run()
