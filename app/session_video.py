"""A session as an mp4 (``lmm-studio view SESSION --video OUT.mp4``): every character of the session replayed
headless in one pass (:class:`lmm.session.player.SessionPlayer`, fingerprints checked as ``replay`` does), drawn
together in the 3D view, with an overlay of the tick, the time and each character's played database frame and
cost (the trace's ``frame`` and ``current_cost``, see :mod:`lmm.session.trace`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: colours of the characters after the first (the first is the viewer's orange; the root path is light blue)
OTHER_COLOURS = ((0.40, 0.78, 0.35), (0.85, 0.45, 0.75), (0.95, 0.85, 0.30))


@dataclass
class SessionMotion:
    controllers: list[str]
    names: list[str]                 # joint names (the database's, without its simulation bone)
    parents: np.ndarray
    positions: dict                  # controller -> (ticks, joints, 3) metres
    frames: dict                     # controller -> (ticks,) played database frame
    costs: dict                      # controller -> (ticks,) current cost
    dt: float


def replay_session(path) -> SessionMotion:
    """Every character's global joint positions at every tick of the session at ``path``."""
    from app.commands.session_common import open_with_database
    from lmm.session.player import SessionPlayer

    session, db, features, weights = open_with_database(path)
    try:
        player = SessionPlayer(session, db, features, weights=weights)
        names = list(player.controllers)
        pos = {n: [] for n in names}
        frames = {n: [] for n in names}
        costs = {n: [] for n in names}
        while not player.done:
            poses, snaps = player.step()
            for n in names:
                pos[n].append(np.asarray(poses[n].global_positions[1:], dtype=np.float32))   # bone 0: simulation
                frames[n].append(int(snaps[n].matched_frame))
                costs[n].append(float(snaps[n].current_cost))
        dt = float(player.dt)
    finally:
        session.close()
    parents = np.asarray(db.parents[1:], dtype=np.int64) - 1          # the hips' parent was bone 0: now -1
    return SessionMotion(names, list(db.names[1:]), parents, {n: np.stack(p) for n, p in pos.items()},
                         {n: np.asarray(f) for n, f in frames.items()}, {n: np.asarray(c) for n, c in costs.items()}, dt)


def overlay_text(motion: SessionMotion, tick: int) -> str:
    parts = [f"tick {tick}  {tick * motion.dt:.2f} s"]
    for n in motion.controllers:
        parts.append(f"{n}: frame {motion.frames[n][tick]}  cost {motion.costs[n][tick]:.3f}")
    return "   ".join(parts)


def draw_overlay(rgb: np.ndarray, text: str) -> np.ndarray:
    """``text`` in the top-left corner of the frame, white on a dark band."""
    from PIL import Image, ImageDraw, ImageFont

    image = Image.fromarray(rgb)
    draw = ImageDraw.Draw(image)
    size = max(10, rgb.shape[0] // 40)
    try:
        font = ImageFont.load_default(size=size)
    except TypeError:                     # Pillow before 10.1: the one bitmap size
        font = ImageFont.load_default()
    box = draw.textbbox((8, 6), text, font=font)
    draw.rectangle((0, 0, rgb.shape[1], box[3] + 6), fill=(20, 22, 26))
    draw.text((8, 6), text, fill=(235, 235, 235), font=font)
    return np.asarray(image)


def write_session_video(args, look, error) -> int:
    """Every character of the session ``args.file`` into the mp4 ``args.video`` (see the module doc)."""
    from app.video import write_video

    motion = replay_session(args.file)
    first, others = motion.controllers[0], motion.controllers[1:]
    n = len(motion.positions[first])
    if not 0 <= args.frame < n:
        error(f"--frame {args.frame} is out of range: {args.file} has {n} ticks")
        return 2
    extra = [(motion.positions[c], OTHER_COLOURS[i % len(OTHER_COLOURS)]) for i, c in enumerate(others)]
    return write_video(args, motion.parents, motion.positions[first], motion.dt, look(args, motion.names), error,
                       others=extra, overlay=lambda tick: overlay_text(motion, tick))
