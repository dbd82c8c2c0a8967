"""File dialogs: one modal dearpygui file dialog per kind of file the studio opens or writes. A chosen
path goes to the handler the studio registered for that kind.

A chosen file never takes the studio down: a handler reports the bad files it expects itself (one line
in the error dialog naming the file and field), and anything it raises all the same (a file deeper or
stranger than the readers foresaw) is reported here as one line naming the file and the studio goes on.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

from .theme import OPAQUE

DIALOGS = {
    # kind -> (title, extensions, default file name)
    "input": ("Replay input CSV", (".csv",), ""),
    "session": ("Open session", (".lmmsession",), ""),
    "reference": ("Open reference BVH", (".bvh", ".gz", ".glb", ".gltf", ".fbx"), ""),
    "preset_load": ("Load tuning preset", (".json",), ""),
    "preset_save": ("Save tuning preset", (".json",), "preset.json"),
    "weights": ("Load LMM weights", (".npz",), ""),
    "layout_load": ("Load layout", (".ini",), ""),
    "layout_save": ("Save layout as", (".ini",), "my_layout.ini"),
    "record": ("Record to", (".bvh",), "take.bvh"),
}


class FileDialogs:
    def __init__(self, dpg, handlers: dict[str, Callable[[str], object]],
                 report_error: Callable[[str, str], None] | None = None):
        missing = set(DIALOGS) - set(handlers)
        if missing:
            raise ValueError(f"no handler for the file dialogs {sorted(missing)}")
        self.dpg = dpg
        self.handlers = handlers
        self.report_error = report_error

    def build(self) -> None:
        dpg = self.dpg
        for kind, (title, exts, default) in DIALOGS.items():
            with dpg.file_dialog(label=title, tag=f"dlg_{kind}", show=False, modal=True, width=700, height=420,
                                 callback=self._on_choice, user_data=kind, default_filename=default,
                                 directory_selector=False):
                for ext in exts:
                    dpg.add_file_extension(ext, color=(180, 220, 140, 255))
                dpg.add_file_extension(".*")
            dpg.bind_item_theme(f"dlg_{kind}", OPAQUE)

    def open(self, kind: str, start_in: str | None = None) -> None:
        """Show the dialog of ``kind``, starting in the folder of ``start_in`` when it exists."""
        if start_in:
            folder = Path(start_in).expanduser().parent
            self.dpg.configure_item(f"dlg_{kind}", default_path=str(folder if folder.is_dir() else Path.cwd()))
        self.dpg.configure_item(f"dlg_{kind}", show=True)

    @property
    def visible(self) -> bool:
        return any(self.dpg.is_item_shown(f"dlg_{k}") for k in DIALOGS)

    def _on_choice(self, sender, app_data, kind):
        path = (app_data or {}).get("file_path_name") or ""
        if path:
            self.handle(kind, path)

    def handle(self, kind: str, path: str) -> bool:
        """What choosing ``path`` in the dialog of ``kind`` does (test scripts call this directly).
        False when the handler failed (reported in the error dialog, never raised)."""
        try:
            return self.handlers[kind](path) is not False
        except (RecursionError, MemoryError) as e:    # e.g. a preset nested 100,000 deep
            message = f"{path}: cannot read the file ({type(e).__name__}: nested too deeply or too large)"
        except Exception as e:
            text = str(e).splitlines()[0] if str(e) else type(e).__name__
            message = text if str(path) in text else f"{path}: {text}"
        if self.report_error is None:
            raise RuntimeError(message)
        self.report_error(DIALOGS[kind][0], message[:500])
        return False
