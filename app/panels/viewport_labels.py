"""The 3D view's text on top of the picture: name labels over the characters' (the ragdoll's, the preview
ghosts') heads, kept from overlapping, the overlay line and the legend."""
from __future__ import annotations

import numpy as np

from .common import COLORS, RAGDOLL_COLOR, SHORT
from .viewport_scene import LEGEND

LABEL_CHAR_PX, LABEL_HEIGHT_PX = 8.5, 17.0      # a character label's size per character at font size 16


def separate_labels(anchors: dict, sizes: dict, gap: float = 2.0) -> dict:
    """Screen positions for text labels so that none overlaps another (pure, for tests).

    ``anchors``: name -> (x, y) top-left where a label wants to be; ``sizes``: name -> (w, h). Labels
    are placed top to bottom; one that would overlap a placed label moves down below it.
    """
    placed: dict = {}
    for name in sorted(anchors, key=lambda n: (anchors[n][1], anchors[n][0])):
        x, y = (float(v) for v in anchors[name])
        w, h = sizes[name]
        moved = True
        while moved:
            moved = False
            for other, (ox, oy) in placed.items():
                ow, oh = sizes[other]
                if x < ox + ow and ox < x + w and y < oy + oh + gap and oy < y + h + gap:
                    y = oy + oh + gap
                    moved = True
        placed[name] = (x, y)
    return placed


class Labels:
    """The text items of the 3D view's drawlist. Only changed options reach dearpygui (``text``: the
    panel's :class:`~app.panels.common.TextCache`; positions move, texts rarely do)."""

    def __init__(self, dpg, text, drawlist: str):
        self.dpg, self.text, self.drawlist = dpg, text, drawlist
        self._legend_items: list[str] = []
        self._preview_labels = 0

    def create(self, h: int) -> None:
        """The label, overlay and legend items, over the image (made once, with the first image)."""
        dpg = self.dpg
        dpg.draw_text((0, 0), "", tag="vp_label_ragdoll", parent=self.drawlist, size=16,
                      color=tuple(int(c * 255) for c in RAGDOLL_COLOR) + (255,))
        for name in COLORS:
            if not dpg.does_item_exist(f"vp_label_{name}"):
                dpg.draw_text((0, 0), SHORT.get(name, name), tag=f"vp_label_{name}", parent=self.drawlist,
                              size=16, color=tuple(int(c * 255) for c in COLORS.get(name, (1, 1, 1))) + (255,))
        dpg.draw_text((8, 6), "", tag="vp_overlay", parent=self.drawlist, size=14, color=(230, 230, 230, 220))
        x = 8
        for text, color in LEGEND:
            dpg.draw_text((x, h - 20), text, tag=f"vp_legend_{x}", parent=self.drawlist, size=13,
                          color=tuple(int(c * 255) for c in color) + (235,))
            self._legend_items.append(f"vp_legend_{x}")
            x += 7 * len(text) + 14

    def keep_legend_at_bottom(self, h: int) -> None:
        for item in self._legend_items:
            pos = self.dpg.get_item_configuration(item)["pos"]
            self.dpg.configure_item(item, pos=(pos[0], h - 20))

    def hide(self, tag: str) -> None:
        self.text.configure(tag, show=False)

    def update(self, view, characters, heads: dict | None, ragdoll: tuple | None, previews: list, camera,
               size: tuple[int, int], dt: float) -> dict:
        """Name labels over the characters' (``heads``: their label anchors when worked out already), the
        ragdoll's (``(controller, head point)`` or None) and the preview ghosts' heads, and the overlay
        line; returns each shown label's ``[x, y, w, h]`` (see :meth:`place`)."""
        wanted = []     # (label key, item tag, text, world point)
        drawings = characters.drawings
        for name in COLORS:
            tag = f"vp_label_{name}"
            snap = view.tick.snapshots.get(name) if view.tick is not None and name in drawings else None
            if snap is None:
                self.hide(tag)
                continue
            text = SHORT.get(name, name) + (" (inspected)" if name == view.inspected and len(drawings) > 1 else "")
            head = heads.get(name) if heads is not None else None
            wanted.append((name, tag, text, characters.label_anchor(name, snap) if head is None else head))
        if ragdoll is not None:
            controller, head = ragdoll
            text = f"ragdoll: physics copy of {SHORT.get(controller, controller)}"
            wanted.append(("ragdoll", "vp_label_ragdoll", text, head))
        else:
            self.hide("vp_label_ragdoll")
        placed = self.place(wanted, previews, camera, size)
        t = view.tick.time_s if view.tick is not None else 0.0
        text = f"{view.mode}  tick {view.tick_number}  t={t:6.2f} s"
        if not view.live:
            text += f"   ({(view.tick_number - view.history.newest_tick) * dt:+.2f} s)"
        self.text.configure("vp_overlay", text=text)
        return placed

    def place(self, wanted: list, previews: list, camera, size: tuple[int, int]) -> dict:
        """Show ``wanted`` (``(label key, item tag, text, world point)``) and one label per preview ghost
        (``previews``: what the preview drawings drew) where their points project, moved apart so that
        none overlaps another; returns each shown label's ``[x, y, w, h]``."""
        dpg, cache = self.dpg, self.text
        w, h = size
        vp = camera.view_projection_rows(w / max(h, 1))
        from viewer.camera import project_points_floats

        wanted = list(wanted)
        for i, p in enumerate(previews):
            tag = f"vp_preview_label_{i}"
            if i >= self._preview_labels:
                dpg.draw_text((0, 0), "", tag=tag, parent=self.drawlist, size=15, color=(150, 240, 150, 255))
                self._preview_labels = i + 1
            wanted.append((tag, tag, p["label"], np.asarray(p["head"], np.float64) + [0, 0.25, 0]))
        for i in range(len(previews), self._preview_labels):
            cache.configure(f"vp_preview_label_{i}", show=False)
        # every label's anchor above a head, projected in one call
        anchors, sizes, texts, tags = {}, {}, {}, {}
        if wanted:
            for (key, tag, text, _), (x, y, ok) in zip(wanted, project_points_floats([wt[3] for wt in wanted],
                                                                                     vp, w, h)):
                if ok and 0 <= x < w and 0 <= y < h:
                    texts[key], tags[key] = text, tag
                    anchors[key] = (float(x) - 12, float(y) - 18)
                    sizes[key] = (LABEL_CHAR_PX * len(text), LABEL_HEIGHT_PX)
                else:
                    cache.configure(tag, show=False)
        placed = separate_labels(anchors, sizes)
        for key, pos in placed.items():
            cache.configure(tags[key], show=True, pos=pos, text=texts[key])
        return {n: [float(pos[0]), float(pos[1]), *map(float, sizes[n])] for n, pos in placed.items()}
