"""``lmm-studio view FILE.bvh``: play a BVH file in a 3D window, or save one frame (``--screenshot``) or an mp4
(``--video``) headless.

Keys in the window: space pause, left/right step (shift: 10 frames), [ ] speed, F follow,
R reframe, C capsules/sticks, S shadow on/off, Home restart, Esc/Q quit; mouse: left-drag orbit,
right/middle-drag pan, wheel zoom.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from app.cli import number_in


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="BVH file (.bvh or .bvh.gz), any units, Y up; glTF (.glb, .gltf) or FBX; "
                                         "or a session file (its first character, replayed headless)")
    parser.add_argument("--screenshot", metavar="PNG",
                        help="render one frame headless (EGL, no display needed) to PNG and exit")
    parser.add_argument("--video", metavar="MP4",
                        help="render the motion headless to an H.264 mp4 from --frame on (needs the video extra)")
    parser.add_argument("--seconds", type=number_in(0.01, 3600.0, unit="s"), default=None,
                        help="with --video: this long (default: to the end of the file)")
    parser.add_argument("--video-fps", type=number_in(1.0, 240.0, unit="Hz"), default=None,
                        help="with --video: frames per second (default: the file's rate; frames by time)")
    parser.add_argument("--frame", type=number_in(0, MAX_FRAME, integer=True), default=0,
                        help=f"frame to start at / to screenshot, 0..{MAX_FRAME} (default 0)")
    parser.add_argument("--width", type=int, default=1280, help="window or image width (default 1280)")
    parser.add_argument("--height", type=int, default=720, help="window or image height (default 720)")
    parser.add_argument("--samples", type=number_in(0, 16, integer=True), default=None,
                        help="multisampling samples, 0 to 16 (0 disables; default 4 on a GPU, 0 on a software renderer)")
    parser.add_argument("--paused", action="store_true", help="start paused")
    parser.add_argument("--no-follow", action="store_true", help="start with the camera not following the root")
    parser.add_argument("--style", choices=("capsules", "sticks"), default="capsules",
                        help="draw the character as a body of shaded capsules (default) or as thin sticks")
    parser.add_argument("--no-shadow", action="store_true", help="no shadow on the ground")
    # for tests and scripted captures of the real window
    parser.add_argument("--frames", type=int, default=None, metavar="N",
                        help="close the window after N frames (for tests)")
    parser.add_argument("--window-screenshot", metavar="PNG", default=None,
                        help="with --frames: save the window's framebuffer after the last frame")


#: largest --width / --height: the image is rendered into one framebuffer of that size (with 4x MSAA
#: colour and depth, ~20 bytes a pixel: 8192 x 8192 is 1.3 GiB), and OpenGL 3.3 drivers in use allow
#: 8192 x 8192 render targets
MAX_IMAGE_SIDE = 8192
#: largest --frame: a BVH file holds at most 10^7 frames (lmm.data.bvh's motion limits keep it below)
MAX_FRAME = 10_000_000


def _error(message: str) -> None:
    print(f"lmm-studio view: error: {message}", file=sys.stderr)


def _has_display() -> bool:
    if sys.platform.startswith("linux"):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def _read(path: str):
    """The animation in a motion file, or a session's first character replayed headless."""
    from app.commands.export_gltf import is_session, replay_to_bvh
    from lmm.data.motion_files import load_motion

    if not is_session(path):
        return load_motion(path)
    import tempfile
    with tempfile.TemporaryDirectory(prefix="lmm-view-") as folder:
        return load_motion(replay_to_bvh(path, folder))


def _load(path: str):
    """(name, parents, joint names, positions (F,J,3), frame_time) or an error message."""
    from lmm.errors import InputError

    try:
        anim = _read(path)
        positions = anim.global_positions()
    except InputError as e:    # a bad BVH file, or not a regular file
        return str(e)
    except (OSError, EOFError) as e:  # missing file, unreadable, broken gzip
        reason = e.strerror if isinstance(e, OSError) and e.strerror else str(e) or type(e).__name__
        return f"{path}: cannot read: {reason}"
    except Exception as e:  # any other surprise in a bad file: a message, not a traceback
        return f"{path}: cannot load: {type(e).__name__}: {e}"
    if anim.n_frames < 1 or positions.ndim != 3 or positions.shape[1] < 1:
        return f"{path}: no frames to show"
    name = Path(path).name
    return name, anim.parents, list(anim.names), positions, float(anim.frame_time)


def _look(args, names) -> dict:
    """How the character is drawn: joint names, the body radii they say, style, shadow."""
    from lmm.skeleton import body_radii

    return {"names": names, "body_radii": body_radii(names), "style": args.style, "shadow": not args.no_shadow}


def _screenshot(args, parents, names, positions) -> int:
    import numpy as np

    from viewer.context import ContextError, create_headless_context
    from viewer.player import AnimationView
    from viewer.renderer import Renderer

    from lmm.data.atomic import check_writable
    from lmm.reporting import write_png

    try:
        check_writable(args.screenshot)      # before the rendering: a read-only target fails at once
    except OSError as e:
        _error(f"{e.filename}: {e.strerror}")
        return 1
    try:
        ctx = create_headless_context()
    except ContextError as e:
        _error(str(e))
        return 1
    view = AnimationView(ctx, parents, positions, aspect=args.width / args.height, follow=not args.no_follow,
                         **_look(args, names))
    view.reset_camera(args.frame)
    view.set_frame(args.frame)
    renderer = Renderer(ctx, args.width, args.height, samples=args.samples)
    image = renderer.render(view.scene, view.camera, dtype=np.uint8)
    out = Path(args.screenshot)
    try:
        write_png(out, image[..., :3])
    except OSError as e:
        _error(f"{e.filename}: {e.strerror}")
        return 1
    print(f"saved frame {args.frame} of {len(positions)} to {out}")
    return 0


def main(args: argparse.Namespace) -> int:
    if not (16 <= args.width <= MAX_IMAGE_SIDE and 16 <= args.height <= MAX_IMAGE_SIDE):
        _error(f"--width and --height must be 16..{MAX_IMAGE_SIDE}, got {args.width}x{args.height}")
        return 2
    if not (args.screenshot or args.video) and not _has_display():
        _error("no display to open a window on (DISPLAY is not set); "
               "use --screenshot PNG to render a frame headless, or run under Xvfb")
        return 2
    from lmm.data.outputs import check_outputs

    from lmm.errors import InputError

    try:
        check_outputs([("--screenshot", args.screenshot), ("--window-screenshot", args.window_screenshot),
                       ("--video", args.video)], [("FILE", args.file)])
        if args.video:
            from app.video import require_imageio_ffmpeg
            require_imageio_ffmpeg()          # before the loading: one line when the extra is missing
    except InputError as e:
        _error(str(e))
        return 1
    except OSError as e:   # a read-only or file-as-folder target
        _error(f"{e.filename}: {e.strerror}")
        return 1
    if args.video:
        from app.commands.export_gltf import is_session
        if is_session(args.file):             # every character, replayed in one pass, with an overlay
            from app.session_video import write_session_video
            return write_session_video(args, _look, _error)
    loaded = _load(args.file)
    if isinstance(loaded, str):
        _error(loaded)
        return 1
    name, parents, names, positions, frame_time = loaded
    n = len(positions)
    if not 0 <= args.frame < n:
        _error(f"--frame {args.frame} is out of range: {args.file} has {n} frames")
        return 2
    args.frame %= n
    if args.screenshot:
        return _screenshot(args, parents, names, positions)
    if args.video:
        from app.video import write_video
        return write_video(args, parents, positions, frame_time, _look(args, names), _error)

    from viewer.window import PlayerWindow, WindowError

    try:
        window = PlayerWindow(parents, positions, frame_time, title=f"lmm-studio view {name}",
                              width=args.width, height=args.height, samples=args.samples,
                              start_frame=args.frame, **_look(args, names))
    except WindowError as e:
        _error(str(e))
        return 2
    window.view.follow = not args.no_follow
    window.playback.paused = args.paused
    if args.window_screenshot:
        from lmm.data.atomic import check_writable
        try:
            check_writable(args.window_screenshot)
        except OSError as e:
            _error(f"{e.filename}: {e.strerror}")
            return 1
    try:
        from lmm.reporting import write_png
        return window.run(max_frames=args.frames, screenshot_path=args.window_screenshot, save_image=write_png)
    except OSError as e:      # the screenshot could not be written after all (e.g. a full disk)
        _error(f"{e.filename}: {e.strerror}")
        return 1
