"""Writing an H.264 mp4 from rendered frames through ``imageio-ffmpeg`` (the ``video`` extra, whose wheel ships an
ffmpeg binary, so nothing else is installed). ``yuv420p`` so every player opens it; the width and height are
made even (H.264 with 4:2:0 chroma needs that). The file appears whole or not at all: ffmpeg writes a temporary
file beside it that is renamed over the target when the last frame is in."""
from __future__ import annotations

import os
import secrets
from pathlib import Path

import numpy as np

from lmm.errors import InputError

class VideoError(InputError):
    """ffmpeg could not write the file (one line)."""


def require_imageio_ffmpeg():
    """The ``imageio_ffmpeg`` module, or a one-line :class:`~lmm.data.motion_files.MissingExtra`."""
    from lmm.data.motion_files import require_extra
    return require_extra("imageio_ffmpeg", "writing a video", "video")


def _first_line(e: Exception) -> str:
    lines = str(e).splitlines()
    return lines[0][:160] if lines else type(e).__name__


def even_size(width: int, height: int) -> tuple[int, int]:
    """The largest even width and height not above the given ones (H.264 4:2:0 needs even sides)."""
    return width - width % 2, height - height % 2


class Mp4Writer:
    """``with Mp4Writer(path, width, height, fps) as w: w.write(rgb)`` for (height, width, 3) uint8 frames."""

    def __init__(self, path, width: int, height: int, fps: float, quality: int = 20):
        ffmpeg = require_imageio_ffmpeg()
        self.path = Path(path)
        self.size = (int(width), int(height))
        if self.size != even_size(*self.size):
            raise ValueError(f"the video's width and height must be even, got {width}x{height}")
        self.tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp.mp4")
        self.frames = 0
        self._gen = ffmpeg.write_frames(str(self.tmp), self.size, fps=float(fps), codec="libx264",
                                        pix_fmt_out="yuv420p", macro_block_size=2,
                                        output_params=["-crf", str(int(quality))], ffmpeg_log_level="error")
        self._gen.send(None)

    def write(self, rgb: np.ndarray) -> None:
        if rgb.shape != (self.size[1], self.size[0], 3) or rgb.dtype != np.uint8:
            raise ValueError(f"a frame is {rgb.shape} {rgb.dtype}, expected ({self.size[1]}, {self.size[0]}, 3) uint8")
        try:
            self._gen.send(np.ascontiguousarray(rgb))
        except (OSError, RuntimeError) as e:
            self._abandon()
            raise VideoError(f"{self.path}: ffmpeg could not write the video ({_first_line(e)})") from None
        self.frames += 1

    def close(self) -> None:
        """Finish the file and rename it over the target."""
        try:
            self._gen.close()
        except (OSError, RuntimeError) as e:
            self._abandon()
            raise VideoError(f"{self.path}: ffmpeg could not finish the video ({_first_line(e)})") from None
        os.replace(self.tmp, self.path)

    def _abandon(self) -> None:
        try:
            self._gen.close()
        except Exception:  # noqa: BLE001 - already failing: the first error is the one reported
            pass
        self.tmp.unlink(missing_ok=True)

    def __enter__(self) -> "Mp4Writer":
        return self

    def __exit__(self, kind, value, tb) -> None:
        if kind is None:
            self.close()
        else:
            self._abandon()


def video_frames(n_frames: int, frame_time: float, start: int, fps: float, seconds: float | None) -> np.ndarray:
    """The file frames a video shows: frame ``start`` at 0 s, then the nearest file frame every 1 / ``fps`` s,
    for ``seconds`` (default: to the end of the file)."""
    available = (n_frames - 1 - start) * frame_time
    length = available if seconds is None else min(float(seconds), available + frame_time)
    count = max(1, int(round(length * fps)) + (1 if seconds is None else 0))
    return np.minimum(start + np.round(np.arange(count) / fps / frame_time).astype(np.int64), n_frames - 1)


def write_video(args, parents, positions, frame_time: float, look: dict, error, others=(), overlay=None) -> int:
    """``lmm-studio view FILE --video OUT.mp4``: the headless renderer's frames (as ``--screenshot`` draws them,
    the camera following the root unless ``--no-follow``) into an mp4. ``others``: more characters of the same
    skeleton, ``(positions, colour)``, drawn beside the first; ``overlay(frame)``: a line of text drawn on top
    (:func:`app.session_video.draw_overlay`). ``error`` prints one line."""
    from viewer.context import ContextError, create_headless_context
    from viewer.player import AnimationView
    from viewer.renderables import Skeleton, radii_for_height
    from viewer.renderer import Renderer

    width, height = even_size(args.width, args.height)
    fps = float(args.video_fps or min(max(1.0 / frame_time, 1.0), 240.0))
    frames = video_frames(len(positions), frame_time, args.frame, fps, args.seconds)
    try:
        ctx = create_headless_context()
    except ContextError as e:
        error(str(e))
        return 1
    view = AnimationView(ctx, parents, positions, aspect=width / height, follow=not args.no_follow, **look)
    view.reset_camera(args.frame)
    extra = [(view.scene.add(Skeleton(ctx, view.parents, color=colour, names=look["names"], style=look["style"],
                                      shadow=look["shadow"], body_radii=look["body_radii"],
                                      **radii_for_height(view.props.height))), np.asarray(pos, np.float32))
             for pos, colour in others]
    renderer = Renderer(ctx, width, height, samples=args.samples)
    image = None
    with Mp4Writer(args.video, width, height, fps) as out:
        for f in frames:
            view.set_frame(int(f))
            for skeleton, pos in extra:
                skeleton.update(pos[int(f)])
            image = renderer.render(view.scene, view.camera, dtype=np.uint8, out=image)
            rgb = image[..., :3]
            if overlay is not None:
                from app.session_video import draw_overlay
                rgb = draw_overlay(np.ascontiguousarray(rgb), overlay(int(f)))
            out.write(rgb)
    print(f"saved {len(frames)} frames ({len(frames) / fps:.2f} s at {fps:g} fps, {width}x{height}) "
          f"from frame {args.frame} of {len(positions)} to {args.video}")
    return 0
