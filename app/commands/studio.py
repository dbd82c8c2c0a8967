"""``lmm-studio`` (or ``lmm-studio studio``): open the studio.

Motion matching and learned motion matching characters driven by the same input, every internal
visible live, every tunable on a slider. ``--frames N --screenshot PATH`` runs N frames, saves a
screenshot of the whole window and exits (tests, documentation).
"""
from __future__ import annotations

import argparse
import os
import sys

from app.cli import number_in


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--manifest", help="database manifest (default: the embedded LAFAN1 locomotion set)")
    parser.add_argument("--weights", help="LMM network weights (.npz; default: the shipped networks)")
    for flag, metavar, text in (
            ("--layout", "NAME|PATH", "window layout: default, compare, tuning or an .ini file (default: your "
                                      "last layout, else 'default')"),
            ("--tuning", "PRESET.json", "start from this tuning preset (partial presets keep the defaults; the "
                                        "Tuning panel's Reset buttons go back to the defaults)"),
            ("--input", "CSV|builtin:NAME", "replay an input log instead of live keyboard/gamepad input (builtin: "
                                            "circle, zigzag, stop-and-go, strafe, turns, random:SEED)"),
            ("--open", "SESSION", "reopen a session file (a recording's take.lmmsession, run --session): the "
                                  "timeline covers it whole and every panel shows the picked tick")):
        parser.add_argument(flag, metavar=metavar, help=text)
    parser.add_argument("--frames", type=number_in(1, 10**7, integer=True), metavar="N", help="run N frames (one 60 Hz tick each), then exit")
    parser.add_argument("--screenshot", metavar="PATH", help="with --frames: save the whole window as PNG at the end")
    parser.add_argument("--width", type=number_in(640, 8192, integer=True), default=1600,
                        help="window width, 640..8192 (default 1600)")
    parser.add_argument("--height", type=number_in(400, 8192, integer=True), default=900,
                        help="window height, 400..8192 (default 900)")
    parser.add_argument("--no-lmm", action="store_true", help="motion matching only")
    parser.add_argument("--no-physics", action="store_true",
                        help="no simulated ragdolls (they need the physics extra: pip install -e '.[physics]')")
    parser.add_argument("--samples", type=number_in(-1, 16, integer=True), default=-1,
                        help="3D view multisampling, e.g. 0 or 4 (default: 4 on a GPU, 0 on software OpenGL)")
    parser.add_argument("--render-scale", type=number_in(0.25, 1.0), default=1.0, metavar="S",
                        help="render the 3D view at S times its size and stretch it (0.25-1; default 1): "
                             "cheaper on software OpenGL")
    parser.add_argument("--readback-3d", action="store_true",
                        help="read the 3D view back and upload it to dearpygui every frame instead of drawing it "
                             "into dearpygui's texture (slower; for comparison, or a GL driver where that fails)")
    parser.add_argument("--ui-antialiasing", choices=("auto", "on", "off"), default="auto",
                        help="anti-aliased lines and shapes in the panels and plots (default auto: on, except on "
                             "software OpenGL, where they cost about a tenth of the frame rate)")
    parser.add_argument("--no-gamepads", action="store_true", help="do not open gamepads (keyboard only)")
    parser.add_argument("--fixed-step", action="store_true",
                        help="one 60 Hz tick per rendered frame (default with --frames/--script: reproducible)")
    # for tests and documentation
    parser.add_argument("--script", metavar="JSON", help=argparse.SUPPRESS)
    parser.add_argument("--dump-state", metavar="JSON", help=argparse.SUPPRESS)
    parser.add_argument("--no-save-layout", action="store_true", help="do not save the window layout on exit")
    parser.add_argument("--write-layouts", metavar="DIR", help=argparse.SUPPRESS)


def _has_display() -> bool:
    if sys.platform.startswith("linux"):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def main(args: argparse.Namespace) -> int:
    if args.screenshot and args.frames is None:
        print("lmm-studio: error: --screenshot needs --frames N", file=sys.stderr)
        return 2
    if args.frames is not None and args.frames < 1:
        print("lmm-studio: error: --frames must be at least 1", file=sys.stderr)
        return 2
    if args.width < 640 or args.height < 400:
        print("lmm-studio: error: the window must be at least 640x400", file=sys.stderr)
        return 2
    if args.open:
        # the session names its database and networks: the studio opens those (one line when it cannot)
        from lmm.errors import InputError
        from lmm.session.reader import open_session

        try:
            f = open_session(args.open)
        except InputError as e:
            print(f"lmm-studio: error: {e}", file=sys.stderr)
            return 1
        args.manifest = args.manifest or f.database["manifest"] or None
        kinds = {kind: weights for kind, weights, _ in f.controllers.values()}
        args.weights = args.weights or kinds.get("lmm") or None
        args.no_lmm = args.no_lmm or "lmm" not in kinds
        args.input = None
        f.close()
    preset = None
    if args.tuning:
        # checked before the window and the database: a bad file is one line and exit status 2
        from lmm.tuning import Tuning, TuningError

        try:
            preset = Tuning.read_preset(args.tuning)
            Tuning.from_preset(preset, args.tuning)
        except TuningError as e:
            print(f"lmm-studio: error: {e}", file=sys.stderr)
            return 2
    if not _has_display():
        # dearpygui aborts the whole process without a display: say so instead
        print("lmm-studio: error: no display (DISPLAY is not set). Run it on a desktop, or under Xvfb: "
              "xvfb-run -a lmm-studio ...", file=sys.stderr)
        return 2
    from app.display import display_problem

    problem = display_problem()
    if problem:   # a display that is not there: dearpygui would abort the process (exit 134)
        print(f"lmm-studio: error: {problem}", file=sys.stderr)
        return 1
    from app import watchdog
    from app.studio import Studio, StudioOptions

    watchdog.arm()   # SIGTERM ends the studio even when it is stuck in native code (10 s to shut down)

    opts = StudioOptions(manifest=args.manifest, weights=args.weights, layout=args.layout, input=args.input,
                         frames=args.frames, screenshot=args.screenshot, width=args.width, height=args.height,
                         lmm=not args.no_lmm, physics=not args.no_physics, script=args.script, dump_state=args.dump_state,
                         fixed_step=args.fixed_step, gamepads=not args.no_gamepads,
                         save_layout=not args.no_save_layout, write_layouts=args.write_layouts,
                         samples=args.samples, render_scale=args.render_scale, readback_3d=args.readback_3d,
                         tuning=args.tuning, tuning_preset=preset, ui_antialiasing=args.ui_antialiasing,
                         open=args.open)
    import numpy as np

    # a network given absurd weights overflows: numpy's warnings were a few lines on every frame (490 in
    # 60 frames); the pose guard reports it once instead (the tick worker's thread does the same)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        return Studio(opts).run()
