"""One PNG of a motion's plausibility (pillow, no matplotlib): root residual force over the frames (with
the 0.3 body-weight line), penetration per foot and sliding per foot with its contacts shaded."""
from __future__ import annotations

import numpy as np

from lmm.physics.plausibility import Plausibility

WIDTH, ROW_HEIGHT, MARGIN = 1000, 180, 50
BACKGROUND, PANEL, TEXT, GRID = (24, 24, 28), (34, 34, 40), (230, 230, 230), (70, 70, 78)
RESIDUAL, LEFT, RIGHT, LIMIT, CONTACT = (240, 200, 80), (90, 170, 250), (250, 140, 60), (200, 70, 70), (50, 60, 50)
RESIDUAL_LIMIT_BW = 0.3


def draw_plausibility_png(result: Plausibility, path, title: str = "") -> None:
    """Write the three plots to ``path`` (atomically)."""
    from PIL import Image, ImageDraw

    from lmm.data.atomic import atomic_write

    rows = [("root residual force (body weights)", [(result.residual_force_bw, RESIDUAL)], RESIDUAL_LIMIT_BW, None),
            ("penetration (cm): left, right", [(result.penetration_cm[:, 0], LEFT), (result.penetration_cm[:, 1], RIGHT)],
             None, None),
            ("sliding in contact (cm/s): left, right; contact shaded",
             [(result.sliding_cm_s[:, 0], LEFT), (result.sliding_cm_s[:, 1], RIGHT)], None, result.contact.any(axis=1))]
    height = MARGIN + len(rows) * (ROW_HEIGHT + MARGIN)
    img = Image.new("RGB", (WIDTH, height), BACKGROUND)
    draw = ImageDraw.Draw(img)
    s = result.summary()
    head = (f"{title}  {result.n_frames} frames at {result.fps:.4g} fps  residual median "
            f"{s.get('residual_force_bw_median', 0):.3f} BW, penetration max {s.get('penetration_cm_max', 0):.1f} cm, "
            f"sliding {s.get('sliding_cm_s_mean_in_contact', 0):.1f} cm/s in contact")
    draw.text((10, 12), head, fill=TEXT)
    n = max(result.n_frames, 2)
    for r, (label, series, limit, shade) in enumerate(rows):
        top = MARGIN + r * (ROW_HEIGHT + MARGIN)
        x0, x1, y0, y1 = 60, WIDTH - 20, top, top + ROW_HEIGHT
        draw.rectangle((x0, y0, x1, y1), fill=PANEL)
        peak = max([float(np.max(v)) if len(v) else 0.0 for v, _ in series] + [limit or 0.0, 1e-6]) * 1.05
        xs = x0 + (x1 - x0) * np.arange(result.n_frames) / (n - 1)
        if shade is not None:
            for i in np.flatnonzero(shade):
                draw.line((xs[i], y0, xs[i], y1), fill=CONTACT)
        if limit is not None:
            y = y1 - (y1 - y0) * limit / peak
            draw.line((x0, y, x1, y), fill=LIMIT)
        for values, colour in series:
            ys = y1 - (y1 - y0) * np.asarray(values) / peak
            draw.line(list(zip(xs.tolist(), ys.tolist())), fill=colour, width=2)
        draw.text((x0, y0 - 16), label, fill=TEXT)
        draw.text((6, y0), f"{peak:.3g}", fill=GRID)
        draw.text((6, y1 - 12), "0", fill=GRID)
    with atomic_write(path, "wb") as f:
        img.save(f, format="PNG")
