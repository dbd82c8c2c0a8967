"""Pictures: every plot and PNG the engine makes, and the one function that encodes and writes a PNG.

The engine's per-tick and data code draws nothing; the commands and the studio hand numbers to this
module. Pillow draws the coverage, data-check and plausibility pictures; matplotlib (an extra, ``eval``
only) the reconstruction and training plots, which are rendered to pixels and written by the same
:func:`write_png`. Numbers come from :mod:`lmm.coverage`, :mod:`lmm.physics.plausibility`,
:mod:`lmm.reconstruction` and :mod:`lmm.offline.evaluation`.

* :func:`write_png`: an image (pillow or an ``(H, W, 3|4)`` uint8 array) as a PNG, written atomically;
* coverage colours and images (numpy; the studio's Coverage panel uses them too) and
  :func:`draw_coverage_png` (map, speed x turn heat map, histograms);
* :func:`draw_speed_turn_png`: the speed x turn heat map alone (``check-data --png``);
* :func:`draw_plausibility_png`: residual force, penetration and sliding over the frames;
* :func:`plot_rotation_errors`, :func:`plot_training`: matplotlib figures (``eval``);
* :func:`draw_lines_png`: stacked line charts (pillow), the A/B comparison of a session (``ab``).
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from lmm.coverage import Coverage, Heatmap, speed_categories

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


# ---------------------------------------------------------------------------------------------------
# PNG output
# ---------------------------------------------------------------------------------------------------

def write_png(path, image) -> Path:
    """Encode ``image`` (a pillow image, or an ``(H, W, 3|4)`` uint8 array) as PNG and write it to ``path``
    whole or not at all (:func:`lmm.data.atomic.write_bytes_atomic`)."""
    from PIL import Image

    from lmm.data.atomic import write_bytes_atomic

    if isinstance(image, np.ndarray):
        image = Image.fromarray(np.ascontiguousarray(image))
    buf = io.BytesIO()
    image.save(buf, format="PNG")
    return write_bytes_atomic(path, buf.getvalue())


def figure_pixels(fig) -> np.ndarray:
    """A matplotlib figure rendered at its dpi as an ``(H, W, 4)`` uint8 array (what ``savefig`` would
    encode), and closed."""
    import matplotlib.pyplot as plt

    fig.canvas.draw()
    pixels = np.array(fig.canvas.buffer_rgba())
    plt.close(fig)
    return pixels


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# ---------------------------------------------------------------------------------------------------
# coverage
# ---------------------------------------------------------------------------------------------------

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


def _draw_heatmap(d, hm: Heatmap, box, font, title: str = "") -> None:
    x0, y0, x1, y1 = box
    d.rectangle(box, fill=PANEL)
    over = f" (over the next {hm.horizon_frames} frames)" if hm.horizon_frames else ""
    d.text((x0 + 8, y0 + 6), title or f"seconds of motion by root speed x turning rate{over}; dark red: none",
           fill=TEXT, font=font)
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
    d.text((x0 + 8, y0), "per-channel histograms of the database's raw feature values (one line per dimension; "
                         "x: the value, from the lowest to the highest, y: frames per bin)", fill=TEXT, font=font)
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

    width, height = 1500, 1120
    img = Image.new("RGB", (width, height), BACKGROUND)
    d = ImageDraw.Draw(img)
    font = _font(d, 13)
    d.text((12, 8), f"coverage of {title or 'the database'}: {cov.n_frames} frames, {cov.n_frames / cov.fps:.0f} s",
           fill=TEXT, font=font)
    _draw_map(img, d, cov, (10, 30, 800, 560), font)
    _draw_heatmap(d, cov.heatmap, (810, 30, width - 10, 560), font)
    _draw_histograms(d, cov, (10, 575, width - 10, height - 10), font)
    return write_png(path, img)


def draw_speed_turn_png(hm: Heatmap, path, title: str = "") -> Path:
    """The speed x turning-rate heat map alone in a PNG at ``path`` (written atomically)."""
    from PIL import Image, ImageDraw

    img = Image.new("RGB", (900, 560), BACKGROUND)
    d = ImageDraw.Draw(img)
    font = _font(d, 13)
    d.text((12, 8), title or f"{float(hm.seconds.sum()):.0f} s of motion", fill=TEXT, font=font)
    _draw_heatmap(d, hm, (10, 30, 890, 550), font)
    return write_png(path, img)


# ---------------------------------------------------------------------------------------------------
# physical plausibility
# ---------------------------------------------------------------------------------------------------

PLAUSIBILITY_WIDTH, PLAUSIBILITY_ROW_HEIGHT, PLAUSIBILITY_MARGIN = 1000, 180, 50
GRID = (70, 70, 78)
RESIDUAL, LEFT, RIGHT, LIMIT, CONTACT = (240, 200, 80), (90, 170, 250), (250, 140, 60), (200, 70, 70), (50, 60, 50)
RESIDUAL_LIMIT_BW = 0.3


def draw_plausibility_png(result, path, title: str = "") -> Path:
    """A motion's plausibility (:class:`lmm.physics.plausibility.Plausibility`) in one PNG: root residual
    force over the frames (with the 0.3 body-weight line), penetration per foot and sliding per foot with
    its contacts shaded; each row's x axis is time in seconds, its y axis the quantity its label names."""
    from PIL import Image, ImageDraw

    width, row_height, margin = PLAUSIBILITY_WIDTH, PLAUSIBILITY_ROW_HEIGHT, PLAUSIBILITY_MARGIN
    rows = [("root residual force (body weights)", [(result.residual_force_bw, RESIDUAL)], RESIDUAL_LIMIT_BW, None),
            ("penetration (cm): left, right", [(result.penetration_cm[:, 0], LEFT), (result.penetration_cm[:, 1], RIGHT)],
             None, None),
            ("sliding in contact (cm/s): left, right; contact shaded",
             [(result.sliding_cm_s[:, 0], LEFT), (result.sliding_cm_s[:, 1], RIGHT)], None, result.contact.any(axis=1))]
    height = margin + len(rows) * (row_height + margin)
    img = Image.new("RGB", (width, height), BACKGROUND)
    draw = ImageDraw.Draw(img)
    s = result.summary()
    head = (f"{title}  {result.n_frames} frames at {result.fps:.4g} fps  residual median "
            f"{s.get('residual_force_bw_median', 0):.3f} BW, penetration max {s.get('penetration_cm_max', 0):.1f} cm, "
            f"sliding {s.get('sliding_cm_s_mean_in_contact', 0):.1f} cm/s in contact")
    draw.text((10, 12), head, fill=TEXT)
    n = max(result.n_frames, 2)
    for r, (label, series, limit, shade) in enumerate(rows):
        top = margin + r * (row_height + margin)
        x0, x1, y0, y1 = 60, width - 20, top, top + row_height
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
        seconds = (n - 1) / result.fps if result.fps else 0.0
        for k in range(5):   # the x axis: time ticks under each row, the last one with its unit
            x = x0 + (x1 - x0) * k / 4
            text = f"{seconds * k / 4:.3g}" + (" s (time)" if k == 4 else "")
            draw.line((x, y1, x, y1 + 4), fill=GRID)
            draw.text((x - (0 if k == 0 else 6 * len(text) if k == 4 else 12), y1 + 5), text, fill=TEXT)
    return write_png(path, img)


# ---------------------------------------------------------------------------------------------------
# evaluation plots (matplotlib)
# ---------------------------------------------------------------------------------------------------

def save_figure(fig, path, dpi: float = 100) -> Path:
    """A matplotlib figure, laid out tightly at ``dpi``, as a PNG at ``path`` (through :func:`write_png`)."""
    fig.set_dpi(dpi)
    fig.tight_layout()
    return write_png(path, figure_pixels(fig))


def plot_rotation_errors(results: list[dict], controller_names, path) -> Path:
    """Rotation error over time per take (one panel each, a line per controller) of the reconstruction
    benchmark (:mod:`lmm.reconstruction`)."""
    plt = _pyplot()
    colors = {"mm": "#f58f29", "lmm": "#38a8ff"}
    fig, axes = plt.subplots(len(results), 1, figsize=(9, 1.9 * len(results)), squeeze=False)
    for ax, r in zip(axes[:, 0], results):
        for k in controller_names:
            e = np.asarray(r["controllers"][k]["per_frame_rotation_error_rad"])
            ax.plot(np.arange(len(e)) / r["compare_fps"], e, color=colors.get(k), lw=1.0, label=k.upper())
        a, b = r["frames"]
        ax.set_title(f"{r['take'].split('/')[-1]} [{a}:{b}] ({r['motion']})", fontsize=8)
        ax.set_ylabel("rad", fontsize=7)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("seconds", fontsize=8)
    return save_figure(fig, path, dpi=100)


def plot_training(out_dir, losses: dict | None, artifacts: dict) -> list[str]:
    """The training and evaluation plots of ``eval`` in ``out_dir``: losses per network (``losses`` from
    :func:`lmm.offline.evaluation.read_loss_csv`), the LMM latent traces and the decompressor's per-joint
    error; the paths written."""
    plt = _pyplot()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []

    def save(fig, name):
        written.append(str(save_figure(fig, out_dir / name, dpi=110)))

    if losses is not None:
        fig, axes = plt.subplots(1, max(len(losses), 1), figsize=(5 * max(len(losses), 1), 3.5), squeeze=False)
        for ax, (name, d) in zip(axes[0], losses.items()):
            ax.semilogy(d["iteration"], d["loss"], label="total", color="k")
            for k, v in d.items():
                if k not in ("iteration", "elapsed_s", "lr", "loss"):
                    ax.semilogy(d["iteration"], v, lw=0.8, alpha=0.7, label=k)
            ax.set_title(name)
            ax.set_xlabel("iteration")
            ax.set_ylabel("loss (log scale)")
            ax.legend(fontsize=5, ncol=2)
        save(fig, "training_losses.png")
    if artifacts.get("latents") is not None:
        lat = artifacts["latents"]
        t = np.arange(lat.shape[0]) * artifacts["dt"]
        fig, ax = plt.subplots(figsize=(9, 3.5))
        for k in range(min(lat.shape[1], 8)):
            ax.plot(t, lat[:, k], lw=0.8, label=f"z{k}")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("latent value")
        ax.set_title("LMM latent (first 8 dims)")
        ax.legend(fontsize=6, ncol=4)
        save(fig, "latent_traces.png")
    if artifacts.get("per_joint_cm"):
        names = list(artifacts["per_joint_cm"])
        vals = [artifacts["per_joint_cm"][n] for n in names]
        fig, ax = plt.subplots(figsize=(9, 3.5))
        ax.bar(range(len(names)), vals)
        ax.set_xticks(range(len(names)))
        ax.set_xticklabels(names, rotation=70, fontsize=7)
        ax.set_xlabel("joint")
        ax.set_ylabel("mean error (cm)")
        ax.set_title("decompressor: character-space joint position error")
        save(fig, "per_joint_error.png")
    return written


# ---------------------------------------------------------------------------------------------------
# line charts (pillow): session comparisons
# ---------------------------------------------------------------------------------------------------

def draw_lines_png(panels, path, title: str = "", width: int = 1100, panel_height: int = 190,
                   marker_x: float | None = None) -> Path:
    """Stacked line charts over one x axis as a PNG: ``panels`` is a list of ``(label, x_label,
    {series name: (x, y)})``; each panel scales to its own finite y range; ``marker_x`` draws a dashed
    vertical line (a branch tick). NaN values leave gaps."""
    from PIL import Image, ImageDraw

    top = 30 if title else 8
    canvas = Image.new("RGB", (width, top + panel_height * len(panels) + 8), BACKGROUND)
    d = ImageDraw.Draw(canvas)
    font = _font(d)
    if title:
        d.text((10, 8), title, fill=TEXT, font=font)
    for p, (label, x_label, series) in enumerate(panels):
        x0, y0 = 8, top + p * panel_height
        box = (x0, y0, width - 8, y0 + panel_height - 8)
        d.rectangle(box, fill=PANEL)
        gx0, gy0, gx1, gy1 = box[0] + 70, box[1] + 26, box[2] - 150, box[3] - 24
        xs = [np.asarray(x, np.float64) for x, _ in series.values()]
        ys = [np.asarray(y, np.float64) for _, y in series.values()]
        finite = np.concatenate([y[np.isfinite(y)] for y in ys] + [np.zeros(0)])
        xall = np.concatenate(xs) if any(x.size for x in xs) else np.zeros(1)
        xlo, xhi = float(xall.min()), float(max(xall.max(), xall.min() + 1e-9))
        ylo, yhi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        if yhi - ylo < 1e-12:
            ylo, yhi = ylo - 0.5, yhi + 0.5
        d.text((box[0] + 8, box[1] + 6), label, fill=TEXT, font=font)
        d.text((box[0] + 8, gy0), f"{yhi:.3g}", fill=DIM_TEXT, font=font)
        d.text((box[0] + 8, gy1 - 12), f"{ylo:.3g}", fill=DIM_TEXT, font=font)
        d.text((gx0, gy1 + 6), f"{xlo:.4g}", fill=DIM_TEXT, font=font)
        d.text((gx1 - 60, gy1 + 6), f"{xhi:.4g} {x_label}", fill=DIM_TEXT, font=font)
        d.line([(gx0, gy1), (gx1, gy1)], fill=DIM_TEXT)

        def px(x, y):
            return (gx0 + (x - xlo) / (xhi - xlo) * (gx1 - gx0), gy1 - (y - ylo) / (yhi - ylo) * (gy1 - gy0))

        if marker_x is not None and xlo <= marker_x <= xhi:
            mx = px(marker_x, ylo)[0]
            for y in range(int(gy0), int(gy1), 8):
                d.line([(mx, y), (mx, y + 4)], fill=DIM_TEXT)
        for i, ((name, _), x, y) in enumerate(zip(series.items(), xs, ys)):
            color = palette(len(PALETTE) - 1 - i)      # the character colours first (orange, blue), then others
            run = []
            for xv, yv in zip(x, y):
                if np.isfinite(yv):
                    run.append(px(xv, yv))
                elif run:
                    d.line(run, fill=color) if len(run) > 1 else d.point(run, fill=color)
                    run = []
            if len(run) > 1:
                d.line(run, fill=color)
            ly = gy0 + 16 * i
            d.rectangle([gx1 + 14, ly + 3, gx1 + 24, ly + 13], fill=color)
            d.text((gx1 + 30, ly), name, fill=TEXT, font=font)
    return write_png(path, canvas)
