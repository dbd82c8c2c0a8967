"""The studio's look: font, the global dearpygui theme, plot series colours, and opaque backgrounds
for windows that overlap another (tiled ones draw none: on software GL that fill costs ~12 ms a frame)."""
from __future__ import annotations

import os

from .panels.common import built_windows, overlapping, window_tag

FONT_CANDIDATES = (
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/noto/NotoSans-Regular.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    "C:/Windows/Fonts/segoeui.ttf",
    "/System/Library/Fonts/Supplemental/Arial.ttf",
    "/Library/Fonts/Arial.ttf",
)

WINDOW_BG = (30, 32, 38, 255)
OPAQUE = "opaque_window"          # theme tag of an opaque window background (dialogs use it too)


class Theme:
    def __init__(self, dpg):
        self.dpg = dpg
        self._series_themes: dict = {}
        self._opaque: set[str] = set()

    def build(self) -> None:
        """Font and global theme; call once after ``create_context``."""
        dpg = self.dpg
        font_path = next((p for p in FONT_CANDIDATES if os.path.isfile(p)), None)
        if font_path:
            with dpg.font_registry():
                font = dpg.add_font(font_path, 15)
            dpg.bind_font(font)
        plots = dpg.mvThemeCat_Plots
        with dpg.theme(tag="studio_theme"):
            with dpg.theme_component(dpg.mvAll):
                dpg.add_theme_style(dpg.mvStyleVar_WindowPadding, 8, 6)
                dpg.add_theme_style(dpg.mvStyleVar_FramePadding, 5, 3)
                dpg.add_theme_style(dpg.mvStyleVar_ItemSpacing, 6, 4)
                dpg.add_theme_style(dpg.mvStyleVar_FrameRounding, 3)
                dpg.add_theme_style(dpg.mvStyleVar_WindowRounding, 2)
                dpg.add_theme_style(dpg.mvStyleVar_GrabRounding, 3)
                # panels tile the window over a clear colour of the same grey, so their own background
                # need not be drawn; windows that overlap another get an opaque one (see backgrounds)
                dpg.add_theme_color(dpg.mvThemeCol_WindowBg, WINDOW_BG[:3] + (0,))
                dpg.add_theme_color(dpg.mvThemeCol_TitleBg, (38, 40, 48, 255))
                dpg.add_theme_color(dpg.mvThemeCol_TitleBgActive, (52, 58, 78, 255))
                dpg.add_theme_color(dpg.mvThemeCol_FrameBg, (44, 47, 56, 255))
                dpg.add_theme_color(dpg.mvThemeCol_Header, (52, 58, 78, 255))
                dpg.add_theme_color(dpg.mvThemeCol_SliderGrab, (110, 150, 220, 255))
                dpg.add_theme_color(dpg.mvThemeCol_Button, (56, 62, 82, 255))
                dpg.add_theme_color(dpg.mvThemeCol_MenuBarBg, (36, 38, 46, 255))
                dpg.add_theme_color(dpg.mvPlotCol_PlotBg, (0, 0, 0, 0), category=plots)
                dpg.add_theme_color(dpg.mvPlotCol_FrameBg, (30, 32, 38, 0), category=plots)
                dpg.add_theme_style(dpg.mvPlotStyleVar_PlotPadding, 4, 4, category=plots)
                dpg.add_theme_style(dpg.mvPlotStyleVar_LabelPadding, 2, 2, category=plots)
                dpg.add_theme_style(dpg.mvPlotStyleVar_FillAlpha, 0.9, category=plots)
        dpg.bind_theme("studio_theme")
        with dpg.theme(tag=OPAQUE):
            with dpg.theme_component(dpg.mvAll):
                dpg.add_theme_color(dpg.mvThemeCol_WindowBg, WINDOW_BG)
                dpg.add_theme_color(dpg.mvThemeCol_ChildBg, WINDOW_BG)

    def series(self, item, color, weight: float | None = None, bar: bool = False, marker: bool = False,
               marker_size: float = 3.0) -> None:
        """Give a plot series a colour (RGB 0..1) and optionally a line weight, bar fill or markers
        (circles of ``marker_size`` pixels)."""
        dpg = self.dpg
        plots = dpg.mvThemeCat_Plots
        key = (tuple(color), weight, bar, marker, marker_size)
        theme = self._series_themes.get(key)
        if theme is None:
            rgba = tuple(int(round(c * 255)) for c in color[:3]) + (255,)
            with dpg.theme() as theme:
                with dpg.theme_component(dpg.mvAll):
                    for col in (dpg.mvPlotCol_Line, dpg.mvPlotCol_Fill, dpg.mvPlotCol_MarkerFill,
                                dpg.mvPlotCol_MarkerOutline):
                        dpg.add_theme_color(col, rgba, category=plots)
                    if weight is not None:
                        dpg.add_theme_style(dpg.mvPlotStyleVar_LineWeight, weight, category=plots)
                    if marker:
                        dpg.add_theme_style(dpg.mvPlotStyleVar_Marker, dpg.mvPlotMarker_Circle, category=plots)
                        dpg.add_theme_style(dpg.mvPlotStyleVar_MarkerSize, float(marker_size), category=plots)
            self._series_themes[key] = theme
        dpg.bind_item_theme(item, theme)

    def backgrounds(self) -> None:
        """Opaque background for panels that overlap another (dragged, floating), none for tiled ones."""
        dpg = self.dpg
        rects = {}
        keys = built_windows(dpg)
        for key in keys:
            tag = window_tag(key)
            if dpg.is_item_shown(tag):
                x, y = dpg.get_item_pos(tag)
                w, h = dpg.get_item_rect_size(tag)
                rects[key] = (x, y, x + w, y + h)
        over = overlapping(rects)
        for key in keys:
            want = key in over
            if want != (key in self._opaque):
                dpg.bind_item_theme(window_tag(key), OPAQUE if want else 0)
                (self._opaque.add if want else self._opaque.discard)(key)
