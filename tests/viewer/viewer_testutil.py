"""Image checks and synthetic skeletons shared by the viewer tests."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

# a T-pose-like skeleton in metres, standing at the origin, facing +Z
TPOSE_PARENTS = np.array([-1, 0, 1, 2, 2, 4, 5, 2, 7, 8, 0, 10, 11, 0, 13, 14])
TPOSE_POSITIONS = np.array([
    [0.0, 1.00, 0.0], [0.0, 1.30, 0.0], [0.0, 1.52, 0.0], [0.0, 1.75, 0.0],        # hips, spine, neck, head
    [0.18, 1.48, 0.0], [0.48, 1.48, 0.0], [0.76, 1.48, 0.0],                       # left arm
    [-0.18, 1.48, 0.0], [-0.48, 1.48, 0.0], [-0.76, 1.48, 0.0],                    # right arm
    [0.1, 0.95, 0.0], [0.1, 0.52, 0.0], [0.1, 0.07, 0.0],                          # left leg
    [-0.1, 0.95, 0.0], [-0.1, 0.52, 0.0], [-0.1, 0.07, 0.0],                       # right leg
])


def rgb_to_hsv(image: np.ndarray):
    """Hue (degrees), saturation and value (0..1) of an (..., 3|4) uint8 image."""
    rgb = image[..., :3].astype(np.float64) / 255.0
    mx, mn = rgb.max(axis=-1), rgb.min(axis=-1)
    delta = mx - mn
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    safe = np.where(delta > 0, delta, 1.0)
    hue = np.where(mx == r, ((g - b) / safe) % 6.0, np.where(mx == g, (b - r) / safe + 2.0, (r - g) / safe + 4.0))
    hue = np.where(delta > 0, hue * 60.0, 0.0)
    sat = np.where(mx > 0, delta / np.where(mx > 0, mx, 1.0), 0.0)
    return hue, sat, mx


def colour_mask(image: np.ndarray, rgb, hue_tol_deg: float = 14.0, min_sat: float = 0.45) -> np.ndarray:
    """Pixels whose hue is that of ``rgb`` (0..1) and clearly saturated: robust to lighting."""
    ref_h, _, _ = rgb_to_hsv((np.asarray(rgb, dtype=np.float64)[None, :3] * 255).astype(np.uint8))
    hue, sat, val = rgb_to_hsv(image)
    dh = np.abs((hue - ref_h[0] + 180.0) % 360.0 - 180.0)
    return (dh <= hue_tol_deg) & (sat >= min_sat) & (val > 0.15)


def near_any(mask: np.ndarray, xy, radius: int) -> bool:
    """Whether ``mask`` is true anywhere within ``radius`` pixels (square) of pixel ``xy``."""
    x, y = int(xy[0]), int(xy[1])
    h, w = mask.shape
    return bool(mask[max(y - radius, 0):min(y + radius + 1, h), max(x - radius, 0):min(x + radius + 1, w)].any())


def segment_distance_map(shape, segments_2d) -> np.ndarray:
    """Distance in pixels from every pixel centre to the nearest of the 2D segments (K, 2, 2)."""
    h, w = shape
    ys, xs = np.mgrid[0:h, 0:w]
    p = np.stack([xs + 0.5, ys + 0.5], axis=-1).reshape(-1, 2)
    best = np.full(len(p), np.inf)
    for a, b in segments_2d:
        ab = b - a
        t = np.clip(((p - a) @ ab) / max(ab @ ab, 1e-12), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(p - (a + t[:, None] * ab), axis=1))
    return best.reshape(h, w)


def mask_bbox(mask: np.ndarray):
    """(x0, y0, x1, y1) of the true pixels (inclusive), or None."""
    ys, xs = np.nonzero(mask)
    if len(xs) == 0:
        return None
    return int(xs.min()), int(ys.min()), int(xs.max()), int(ys.max())


def write_bvh(path, names, parents, offsets, root_positions, frame_time=1 / 30, rotations_deg=None):
    """A minimal BVH writer (ZXY rotation channels, root with positions) for synthetic files."""
    names, parents = list(names), list(parents)
    offsets = np.asarray(offsets, dtype=float)
    frames = len(root_positions)
    rot = np.zeros((frames, len(names), 3)) if rotations_deg is None else np.asarray(rotations_deg, dtype=float)
    children = {j: [k for k, p in enumerate(parents) if p == j] for j in range(len(names))}
    lines = ["HIERARCHY"]

    def emit(j, depth):
        pad = "  " * depth
        head = "ROOT" if parents[j] < 0 else "JOINT"
        lines.append(f"{pad}{head} {names[j]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {offsets[j][0]:.6f} {offsets[j][1]:.6f} {offsets[j][2]:.6f}")
        if parents[j] < 0:
            lines.append(f"{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
        else:
            lines.append(f"{pad}  CHANNELS 3 Zrotation Xrotation Yrotation")
        if children[j]:
            for c in children[j]:
                emit(c, depth + 1)
        else:
            tip = offsets[j] if np.linalg.norm(offsets[j]) > 0 else np.array([0.0, 1.0, 0.0])
            lines.append(f"{pad}  End Site")
            lines.append(f"{pad}  {{")
            lines.append(f"{pad}    OFFSET {tip[0] * 0.5:.6f} {tip[1] * 0.5:.6f} {tip[2] * 0.5:.6f}")
            lines.append(f"{pad}  }}")
        lines.append(f"{pad}}}")

    emit(0, 0)
    lines += ["MOTION", f"Frames: {frames}", f"Frame Time: {frame_time:.6f}"]
    for f in range(frames):
        values = list(root_positions[f]) + list(rot[f, 0])
        for j in range(1, len(names)):
            values += list(rot[f, j])
        lines.append(" ".join(f"{v:.6f}" for v in values))
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def view_command() -> list[str]:
    """How to run ``lmm-studio view`` from a subprocess, with or without the installed script."""
    return [sys.executable, "-m", "app.cli", "view"]


def run_view(args, env=None, timeout=120) -> subprocess.CompletedProcess:
    base = dict(os.environ if env is None else env)
    base["PYTHONPATH"] = str(ROOT) + os.pathsep + base.get("PYTHONPATH", "")
    return subprocess.run(view_command() + [str(a) for a in args], cwd=ROOT, env=base, capture_output=True,
                          text=True, timeout=timeout)
