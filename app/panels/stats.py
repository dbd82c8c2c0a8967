"""Stats: frames per second, the time each part of a frame takes (controllers with their search and
network parts, the 3D render and its copy into dearpygui's texture, panel updates, dearpygui's own
frame), and the memory motion matching and learned motion matching keep; with a branch of a reopened
session (Edit > Branch here: :mod:`app.branch_view`), A against B at the shown tick."""
from __future__ import annotations

import functools
import os

import numpy as np

from .base import Panel, View
from .common import COLORS, SHORT, fmt_bytes

PARTS = ("input", "mm", "lmm", "viewport", "render", "readback", "panels", "ui")
PART_LABELS = {"input": "input", "mm": "MM step", "lmm": "LMM step", "viewport": "3D scene",
               "render": "3D render", "readback": "3D to texture", "panels": "panels",
               "ui": "UI (dearpygui)"}


def rss_bytes() -> int:
    """Resident memory of this process (Linux /proc; 0 elsewhere)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


@functools.lru_cache(maxsize=64)
def _axis(start: int, stop: int) -> np.ndarray:
    """``np.arange(start, stop)`` as floats, shared (never written to): the plot's x values."""
    x = np.arange(start, stop, dtype=np.float64)
    x.flags.writeable = False
    return x


def branch_text(row: dict | None) -> str:
    """The branch row (pure, for tests): ``app.branch_view.BranchView.difference``'s dict, or None."""
    if row is None:
        return ""
    if row["tick"] < row["from_tick"]:
        return f"branch B from tick {row['from_tick']}: before it, B is A"
    flags = ["jump" if t else "-" for t in row["transitioned"]]
    return (f"A vs B (from tick {row['from_tick']}), tick {row['tick']}: pose difference mean "
            f"{row['mean_difference_m']:.3f} m, max {row['max_difference_m']:.3f} m; cost A {row['cost'][0]:.3f}"
            f" B {row['cost'][1]:.3f}; frame A {row['frames'][0]} B {row['frames'][1]}; transition A {flags[0]}"
            f" B {flags[1]}")


class StatsPanel(Panel):
    key = "stats"
    commands = ("branch_difference",)
    reads = ("frame", "frame_times", "history", "render_info", "snap", "tick")
    branch_text = ""
    quality_text = ""
    _last_text_frame = -100
    _last_limit_frame = -100

    def build(self, window_kwargs: dict) -> None:
        dpg = self.dpg
        with self.window(window_kwargs):
            dpg.add_text("", tag="stats_fps", color=(140, 230, 140))
            dpg.add_text("", tag="stats_branch", color=(240, 180, 90), wrap=0)
            # the motion quality first: what a user tuning the motion reads (the costs and memory below it)
            dpg.add_text("", tag="stats_quality", color=(200, 190, 140), wrap=0)
            dpg.add_text("", tag="stats_memory")
            with dpg.table(header_row=False, borders_innerV=True, policy=dpg.mvTable_SizingStretchProp,
                           tag="stats_table"):
                for _ in range(2):
                    dpg.add_table_column(init_width_or_weight=1.4)
                    dpg.add_table_column(init_width_or_weight=0.8)
                pairs = [PARTS[i:i + 2] for i in range(0, len(PARTS), 2)]
                for pair in pairs:
                    with dpg.table_row():
                        for part in pair:
                            dpg.add_text(PART_LABELS[part], color=(170, 170, 180))
                            dpg.add_text("-", tag=f"stats_ms_{part}")
            dpg.add_text("", tag="stats_detail", color=(170, 170, 180))
            dpg.add_text("", tag="stats_memory_detail", color=(150, 150, 160))
            dpg.add_text("", tag="stats_process", color=(150, 150, 160))
            with dpg.plot(tag="stats_plot", height=-1, width=-1, no_menus=True, no_mouse_pos=True):
                dpg.add_plot_legend(location=dpg.mvPlot_Location_NorthWest, horizontal=True)
                dpg.add_plot_axis(dpg.mvXAxis, tag="stats_x", no_tick_labels=True)
                with dpg.plot_axis(dpg.mvYAxis, tag="stats_y", label="ms"):
                    z = [0.0]
                    dpg.add_line_series(z, z, tag="stats_frame", label="frame")
                    dpg.add_line_series(z, z, tag="stats_mm", label="MM")
                    dpg.add_line_series(z, z, tag="stats_lmm", label="LMM")
        self.ctx.theme.series("stats_frame", (0.85, 0.85, 0.85), weight=1.5)
        self.ctx.theme.series("stats_mm", COLORS["mm"], weight=1.5)
        self.ctx.theme.series("stats_lmm", COLORS["lmm"], weight=1.5)

    def update(self, view: View) -> None:
        dpg = self.dpg
        self.branch_text = branch_text(self.ctx.actions.branch_difference())   # A vs B at the shown tick
        self.text.set("stats_branch", self.branch_text)
        ft = view.frame_times
        if ft is None:
            return
        # numbers change every frame but nobody reads them that fast: refresh the text 4 times a second
        if view.frame - self._last_text_frame >= 15:
            self._last_text_frame = view.frame
            fps = ft.fps()
            python_ms = sum(ft.median(p) for p in ("input", "viewport", "panels") if np.isfinite(ft.median(p)))
            self.text.set("stats_fps", f"{fps:5.1f} fps   frame {ft.median():.1f} ms   Python "
                                       f"{python_ms:.1f} ms")
            for part in PARTS:
                ms = ft.median(part)
                self.text.set(f"stats_ms_{part}", "-" if not np.isfinite(ms) else f"{ms:6.2f} ms")
            details = []
            if view.tick is not None:
                for name in self.ctx.engine.controller_names():
                    s = view.snap(name)
                    if s is not None and s.timings_us:
                        keys = [k for k in s.timings_us if k not in ("total",)]
                        details.append(f"{SHORT.get(name, name)}: " + ", ".join(
                            f"{k} {s.timings_us[k]:.0f}" for k in keys[:4]) + " us")
            self.text.set("stats_detail", "\n".join(details))
            lines = []
            memory = self.ctx.engine.memory()
            for name, parts in memory.items():
                total = sum(parts.values())
                inner = ", ".join(f"{k.replace('_', ' ')} {fmt_bytes(v)}" for k, v in parts.items())
                lines.append(f"{SHORT.get(name, name)} {fmt_bytes(total)}" + (f" ({inner})" if inner else ""))
            totals = {n: sum(p.values()) for n, p in memory.items()}
            head = "memory  "
            if totals.get("mm") and totals.get("lmm"):
                head += f"MM {fmt_bytes(totals['mm'])} vs LMM {fmt_bytes(totals['lmm'])} " \
                        f"({totals['mm'] / max(totals['lmm'], 1):.1f}x)"
            self.text.set("stats_memory", head if totals.get("lmm") else "memory  " + lines[0])
            self.text.set("stats_memory_detail", "\n".join(lines))
            h, dt = view.history, self.ctx.engine.dt
            self.quality_text = self.ctx.engine.quality_text()
            self.text.set("stats_quality", self.quality_text)
            self.text.set("stats_process", f"process {fmt_bytes(rss_bytes())}; history {len(h) * dt:.1f}"
                                           f" of {h.capacity * dt:.0f} s; {view.render_info}")
            self.last = {"fps": fps, "frame_ms": ft.median(), "python_ms": python_ms,
                         "parts_ms": {p: ft.median(p) for p in PARTS},
                         "memory": {n: dict(p) for n, p in memory.items()}}
        y = ft.series()
        if len(y):
            dpg.set_value("stats_frame", [_axis(0, len(y)), y])
            for part, tag in (("mm", "stats_mm"), ("lmm", "stats_lmm")):
                yy = ft.series(part)
                if len(yy):
                    dpg.set_value(tag, [_axis(len(y) - len(yy), len(y)), yy])
            self.text.axis_limits("stats_x", 0.0, float(ft.n))
            if view.frame - self._last_limit_frame >= 15 or len(y) <= 5:
                # the y range follows the 95th percentile, as the text, 4 times a second
                self._last_limit_frame = view.frame
                top = ft.percentile(95) * 1.3 if len(y) > 5 else 50.0
                self.text.axis_limits("stats_y", 0.0, max(top, 20.0))

    def state(self) -> dict:
        return {**self.last, "branch": self.branch_text, "quality": self.quality_text}
