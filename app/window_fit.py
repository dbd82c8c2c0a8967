"""Panels follow the window's size: when the user resizes the studio's window, every panel window is
scaled by the change, the way a layout is fitted at start (app.layout_files.scaled), so the tiling
stays whole and nothing is left outside or a strip left empty (before, only Layout > Default re-fitted
them). What the user arranged is kept: the windows' own places and sizes are scaled, not the layout's."""
from __future__ import annotations

from . import layout_files
from .panels.common import built_windows, window_tag


class WindowFit:
    def __init__(self, dpg):
        self.dpg = dpg
        self.size: tuple[int, int] | None = None     # the window's client size the panels fit

    def check(self) -> bool:
        """Scale the panels when the window's size changed since the last check (True when it did)."""
        dpg = self.dpg
        size = (int(dpg.get_viewport_client_width() or 0), int(dpg.get_viewport_client_height() or 0))
        if 0 in size or size == self.size:
            return False
        old, self.size = self.size, size
        if old is None:
            return False
        for key in built_windows(dpg):
            tag = window_tag(key)
            pos, dims = dpg.get_item_pos(tag), (dpg.get_item_width(tag), dpg.get_item_height(tag))
            new_pos, new_dims = layout_files.scaled(pos, dims, old, size)
            dpg.set_item_pos(tag, new_pos)
            dpg.configure_item(tag, width=new_dims[0], height=new_dims[1])
        return True
