"""Pictures of a database's coverage: the colours and images (numpy; the studio's Coverage panel uses
them too) and one PNG (pillow) with the 2D feature map coloured by tag, the root speed x turning-rate
heat map and the per-channel histograms. Numbers: :mod:`lmm.coverage`."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from lmm.coverage import Coverage, speed_categories

BACKGROUND = (24, 24, 28)
PANEL = (34, 34, 40)
TEXT = (230, 230, 230)
DIM_TEXT = (165, 165, 170)
EMPTY_CELL = (60, 22, 22)
#: category colours (tags, speed classes, histogram dimensions), distinguishable on a dark background;
#: the studio's character colours (orange, blue) come last, so the first eight never look like a character
PALETTE = ((0.40, 0.80, 0.40), (0.90, 0.33, 0.40), (0.70, 0.55, 0.95), (0.95, 0.85, 0.30), (0.35, 0.85, 0.80),
           (0.95, 0.55, 0.80), (0.65, 0.65, 0.65), (0.60, 0.45, 0.30), (0.30, 0.69, 0.95), (0.96, 0.56, 0.16))


#: the map colour of frames the search may not pick (their tags are excluded): dim, not a class colour
EXCLUDED_COLOR = (0.32, 0.32, 0.36)


def palette(i: int) -> tuple[int, int, int]:
    c = PALETTE[i % len(PALETTE)]
    return int(c[0] * 255), int(c[1] * 255), int(c[2] * 255)


def heat_colors(fraction) -> np.ndarray:
    """(..., 3) uint8 colours for cells' shares of the fullest cell (sqrt scale): dark blue (little)
    -> teal -> yellow (most); cells holding nothing (share 0) are dark red."""
    a = np.sqrt(np.clip(np.asarray(fraction, np.float64), 0.0, 1.0))
    stops = np.array([(30, 40, 90), (30, 140, 140), (240, 220, 80)], np.float64)
    t = a * 2.0
    k = np.minimum(t.astype(np.int64), 1)
    c = stops[k] + (stops[k + 1] - stops[k]) * (t - k)[..., None]
    c[a <= 0] = EMPTY_CELL
    return np.round(c).astype(np.uint8)


def map_categories(cov: Coverage, mode: str, max_classes: int = 8) -> tuple[list[str], np.ndarray]:
    """Labels and each frame's class on the map: ``tag`` (each frame's most specific tag) or ``speed``
    (root speed classes); beyond ``max_classes`` the last class holds the rest."""
    if mode == "speed":
        labels, cat = speed_categories(cov.speed_m_s)
    else:
        labels, cat = cov.tag_names, cov.frame_tag
    labels = list(labels)
    if len(labels) > max_classes:
        labels = labels[:max_classes - 1] + [f"{len(labels) - max_classes + 1} more"]
        cat = np.minimum(cat, max_classes - 1)
    return labels, np.asarray(cat, np.int64)


def map_bounds(cov: Coverage, margin: float = 0.03) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) corners of the map's image: every frame inside, with a small margin."""
    lo, hi = cov.map_xy.min(axis=0), cov.map_xy.max(axis=0)
    pad = np.maximum(hi - lo, 1e-6) * margin
    return lo - pad, hi + pad


def map_image(cov: Coverage, cat: np.ndarray, width: int, height: int, excluded=None) -> np.ndarray:
    """(height, width, 4) float32 RGBA image of every frame on the map (within :func:`map_bounds`),
    highest PC2 first: each texel in the colour of the class most of its frames belong to, brighter
    where more frames are, transparent (and black) where none is. ``excluded`` ((N,) bool): frames the
    search may not pick (excluded tags), a class of their own drawn in :data:`EXCLUDED_COLOR`. The
    studio draws it as one textured quad, far cheaper than tens of thousands of markers; the PNG pastes
    it."""
    lo, hi = map_bounds(cov)
    size = np.array([width, height])
    ij = np.clip(np.floor((cov.map_xy - lo) / (hi - lo) * size).astype(np.int64), 0, size - 1)
    row = height - 1 - ij[:, 1]
    n_cat = int(cat.max()) + 1 if len(cat) else 1
    colors = [PALETTE[i % len(PALETTE)] for i in range(n_cat)]
    if excluded is not None and np.any(excluded):
        cat = np.where(excluded, n_cat, cat)
        n_cat += 1
        colors.append(EXCLUDED_COLOR)
    counts = np.bincount((row * width + ij[:, 0]) * n_cat + cat, minlength=width * height * n_cat)
    counts = counts.reshape(width * height, n_cat)
    total = counts.sum(axis=1)
    colors = np.array(colors, np.float32)
    rgb = colors[np.argmax(counts, axis=1)]
    shade = np.where(total > 0, 0.7 + 0.3 * np.log1p(total) / np.log1p(max(int(total.max()), 1)), 0.0)
    img = np.concatenate([rgb * shade[:, None], (total > 0).astype(np.float32)[:, None]], axis=1)
    return np.ascontiguousarray(img.reshape(height, width, 4).astype(np.float32))


def category_centres(cov: Coverage, cat: np.ndarray, n: int) -> np.ndarray:
    """(n, 2) median map position of each class's frames (nan for a class without frames)."""
    out = np.full((n, 2), np.nan)
    for i in range(n):
        sel = cat == i
        if sel.any():
            out[i] = np.median(cov.map_xy[sel], axis=0)
    return out


def _font(d, size: int = 13):
    from PIL import ImageFont

    try:  # pillow's scalable font (10.1+); the old bitmap one squeezes spaces away
        return ImageFont.load_default(size=size)
    except TypeError:  # pragma: no cover - older pillow
        return ImageFont.load_default()


def _draw_map(canvas, d, cov: Coverage, box, font) -> None:
    from PIL import Image

    x0, y0, x1, y1 = box
    d.rectangle(box, fill=PANEL)
    ratio = cov.pca.variance_ratio
    d.text((x0 + 8, y0 + 6), f"feature space map (PCA of the normalised, weighted features): "
                             f"PC1 {100 * ratio[0]:.0f}%, PC2 {100 * ratio[1]:.0f}% of the variance",
           fill=TEXT, font=font)
    px0, py0, px1, py1 = x0 + 40, y0 + 30, x1 - 130, y1 - 30
    labels, cat = map_categories(cov, "tag", len(PALETTE))
    img = map_image(cov, cat, int(px1 - px0), int(py1 - py0))
    rgb = (np.clip(img[..., :3], 0, 1) * 255).astype(np.uint8)
    rgb[img[..., 3] == 0] = PANEL
    canvas.paste(Image.fromarray(rgb, "RGB"), (int(px0), int(py0)))
    d.text((px0, py1 + 8), "PC1", fill=DIM_TEXT, font=font)
    d.text((x0 + 8, py0), "PC2", fill=DIM_TEXT, font=font)
    for i, name in enumerate(labels):
        ly = py0 + 18 * i
        d.rectangle([px1 + 20, ly + 3, px1 + 30, ly + 13], fill=palette(i))
        d.text((px1 + 36, ly), name, fill=TEXT, font=font)


def _draw_heatmap(d, cov: Coverage, box, font) -> None:
    x0, y0, x1, y1 = box
    d.rectangle(box, fill=PANEL)
    hm = cov.heatmap
    d.text((x0 + 8, y0 + 6), f"seconds of motion by root speed x turning rate (over the next {hm.horizon_frames} "
                             f"frames); dark red: none", fill=TEXT, font=font)
    rows, cols = hm.seconds.shape
    gx0, gy0, gx1, gy1 = x0 + 60, y0 + 30, x1 - 12, y1 - 40
    cw, ch = (gx1 - gx0) / cols, (gy1 - gy0) / rows
    colors = heat_colors(hm.seconds / max(float(hm.seconds.max()), 1e-9))
    for i in range(rows):
        y = gy1 - (i + 1) * ch             # faster rows on top
        for j in range(cols):
            color = tuple(int(v) for v in colors[i, j])
            d.rectangle([gx0 + j * cw, y, gx0 + (j + 1) * cw - 1, y + ch - 1], fill=color)
    se, te = hm.speed_edges_m_s, hm.turn_edges_deg_s
    for i in range(0, rows, 4):
        d.text((x0 + 8, gy1 - i * ch - 7), f"{se[i]:g}", fill=DIM_TEXT, font=font)
    for j in range(0, cols + 1, 4):
        d.text((gx0 + j * cw - 12, gy1 + 4), f"{te[j]:g}", fill=DIM_TEXT, font=font)
    d.text((x0 + 8, gy0 - 2), "speed", fill=DIM_TEXT, font=font)
    d.text((x0 + 8, gy0 + 12), "(m/s)", fill=DIM_TEXT, font=font)
    d.text((gx0 + (gx1 - gx0) / 2 - 60, gy1 + 20), "turning rate (deg/s)", fill=DIM_TEXT, font=font)


def _draw_histograms(d, cov: Coverage, box, font) -> None:
    x0, y0, x1, y1 = box
    d.text((x0 + 8, y0), "per-channel histograms of the database's raw feature values (one line per dimension)",
           fill=TEXT, font=font)
    hists = cov.histograms
    ncols = 4
    nrows = max((len(hists) + ncols - 1) // ncols, 1)
    w = (x1 - x0) / ncols
    h = (y1 - y0 - 20) / nrows
    for k, hist in enumerate(hists):
        cx0 = x0 + (k % ncols) * w + 4
        cy0 = y0 + 20 + (k // ncols) * h + 4
        cx1, cy1 = cx0 + w - 8, cy0 + h - 8
        d.rectangle([cx0, cy0, cx1, cy1], fill=PANEL)
        unit = f" ({hist.unit})" if hist.unit else ""
        d.text((cx0 + 6, cy0 + 4), hist.name + unit, fill=TEXT, font=font)
        px0, py0, px1, py1 = cx0 + 8, cy0 + 24, cx1 - 8, cy1 - 20
        lo, hi = float(hist.edges[:, 0].min()), float(hist.edges[:, -1].max())
        span = max(hi - lo, 1e-9)
        peak = max(float(hist.counts.max()), 1.0)
        for di in range(len(hist.dims)):
            e, c = hist.edges[di], hist.counts[di]
            centres = (e[:-1] + e[1:]) / 2
            pts = [(px0 + (x - lo) / span * (px1 - px0), py1 - n / peak * (py1 - py0)) for x, n in zip(centres, c)]
            d.line(pts, fill=palette(di), width=2)
        d.text((px0, py1 + 4), f"{lo:.2f}", fill=DIM_TEXT, font=font)
        d.text((px1 - 40, py1 + 4), f"{hi:.2f}", fill=DIM_TEXT, font=font)
        lx = px0 + 60
        for di, label in enumerate(hist.dims):  # each dimension's label in its line's colour
            d.text((lx, py1 + 4), label, fill=palette(di), font=font)
            lx += 7 * len(label) + 8


def draw_coverage_png(cov: Coverage, path, title: str = "") -> Path:
    """Map, heat map and histograms in one PNG at ``path`` (written atomically)."""
    from PIL import Image, ImageDraw

    from lmm.data.atomic import atomic_write

    width, height = 1500, 1120
    img = Image.new("RGB", (width, height), BACKGROUND)
    d = ImageDraw.Draw(img)
    font = _font(d, 13)
    d.text((12, 8), f"coverage of {title or 'the database'}: {cov.n_frames} frames, {cov.n_frames / cov.fps:.0f} s",
           fill=TEXT, font=font)
    _draw_map(img, d, cov, (10, 30, 800, 560), font)
    _draw_heatmap(d, cov, (810, 30, width - 10, 560), font)
    _draw_histograms(d, cov, (10, 575, width - 10, height - 10), font)
    path = Path(path)
    with atomic_write(path) as f:
        img.save(f, format="PNG")
    return path
