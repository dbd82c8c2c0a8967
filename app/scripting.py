"""Test hooks: a script of timed commands the studio runs (``--script``) and the screenshots it saves.
The GUI tests drive the real studio with these; the state dump they read is :mod:`app.state_dump`."""
from __future__ import annotations

import json
import os
from pathlib import Path

from lmm.data.jsonio import write_json

from .command_registry import CommandRegistry


class Script:
    """Timed commands: ``[{"frame": 30, "do": "set_tuning", "field": ..., "value": ...}, ...]``.

    ``do`` is a command id of :mod:`app.studio_commands` (the one list: ``set_tuning``, ``key_down``,
    ``record_start``, ``layout``, ``follow``, ``pause``, ``scrub``, ``open``, ``capture``, ``screenshot``,
    ``database``, ``motion_search``, ``ragdoll``, ...); the action's other keys are its keyword arguments.
    The runner keeps the keys a script holds down, the labels to capture after this frame's panels
    updated and the files whose existence ends the run.
    """

    def __init__(self, actions: list[dict]):
        self.actions = sorted(actions, key=lambda a: int(a.get("frame", 0)))
        self.i = 0
        self.quit_files: list[Path] = []
        self.keys: set[str] = set()           # keys the script holds down
        self.captures: list[str] = []         # labels to capture after this frame's panels updated

    #: a script is a few hundred actions; a FIFO or /dev/zero given as one blocked or grew without limit
    MAX_BYTES = 16 << 20

    @classmethod
    def load(cls, path) -> "Script":
        from lmm.data.reading import read_limited

        data = json.loads(read_limited(path, cls.MAX_BYTES, "studio script").decode("utf-8"))
        return cls(data["actions"] if isinstance(data, dict) else data)

    def quit_when_exists(self, path) -> None:
        """External tests (real key presses) end the run by creating a file."""
        self.quit_files.append(Path(path))

    def run(self, commands: CommandRegistry, frame: int) -> None:
        """Run the actions due at ``frame`` (and quit when a watched file exists)."""
        if any(p.exists() for p in self.quit_files):
            commands.run("quit")
        while self.i < len(self.actions) and int(self.actions[self.i].get("frame", 0)) <= frame:
            a = self.actions[self.i]
            self.i += 1
            if a["do"] not in commands:
                raise ValueError(f"unknown script action {a['do']!r}")
            commands.run(a["do"], **{k: v for k, v in a.items() if k not in ("frame", "do")})


def write_rects(dpg, path, items) -> None:
    """The screen rectangles of ``items`` as JSON (for tests that click them with xdotool)."""
    write_json(path, {item: list(dpg.get_item_rect_min(item)) + list(dpg.get_item_rect_max(item))
                      for item in items})


class Screenshots:
    """PNG files of the whole window (``--screenshot``, the ``screenshot`` script action)."""

    def __init__(self, dpg):
        self.dpg = dpg
        self.requested: list[Path] = []
        self._temporary: dict[Path, Path] = {}     # target -> the file dearpygui writes first
        self._failed: list[str] = []               # one line per target that cannot be written

    def request(self, path) -> Path:
        """Ask dearpygui to save the whole window during the next frame it renders. dearpygui writes
        a hidden temporary file beside the target, renamed over it once complete (:meth:`finish`),
        so a full disk or a crash never leaves half a PNG under the target's name; a target that
        cannot be written is reported by :meth:`finish`."""
        from lmm.data.atomic import check_writable

        out = Path(path)
        try:
            check_writable(out)
        except OSError as e:
            self._failed.append(f"{e.filename}: {e.strerror}")
            return out
        tmp = out.with_name(f".{out.name}.{os.getpid()}.partial.png")
        tmp.unlink(missing_ok=True)
        self.dpg.output_frame_buffer(file=str(tmp))
        self.requested.append(out)
        self._temporary[out] = tmp
        return out

    def finish(self, report_error) -> int:
        """Render (without simulating) until every requested file is on disk; 1 when one never came."""
        def done(p):
            return self._temporary[p].exists() or (p.exists() and not self._temporary[p].exists())

        pending = [p for p in self.requested if not done(p)]
        tries = 0
        while pending and tries < 5:
            self.dpg.render_dearpygui_frame()
            tries += 1
            pending = [p for p in pending if not done(p)]
        for out, tmp in list(self._temporary.items()):
            if tmp.exists():
                try:
                    os.replace(tmp, out)
                except OSError as e:
                    tmp.unlink(missing_ok=True)
                    self._failed.append(f"{out}: cannot write ({e.strerror})")
        for p in pending:
            report_error("Screenshot", f"{p}: dearpygui did not write the screenshot")
        for line in self._failed:
            report_error("Screenshot", line)
        failed = bool(pending or self._failed)
        self._temporary.clear()
        self._failed = []
        return 1 if failed else 0
