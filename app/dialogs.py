"""File dialogs: one modal dearpygui file dialog per kind of file the studio opens or writes. A chosen
path goes to the handler the studio registered for that kind.

A chosen file never takes the studio down: a handler reports the bad files it expects itself (one line
in the error dialog naming the file and field), and anything it raises all the same (a file deeper or
stranger than the readers foresaw) is reported here as one line naming the file and the studio goes on.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Callable

from .theme import OPAQUE

DIALOGS = {
    # kind -> (title, extensions, default file name)
    "input": ("Replay input CSV", (".csv",), ""),
    "session": ("Open session", (".lmmsession",), ""),
    "reference": ("Open reference BVH", (".bvh", ".gz", ".glb", ".gltf", ".fbx"), ""),
    "preset_load": ("Load tuning preset", (".json",), ""),
    "preset_save": ("Save tuning preset", (".json",), "tuning.json"),
    "weights": ("Load LMM weights", (".npz",), ""),
    "layout_load": ("Load layout", (".ini",), ""),
    "layout_save": ("Save layout as", (".ini",), "my_layout.ini"),
    "record": ("Record to", (".bvh",), "take.bvh"),
}
#: the dialogs that write a file the user names: they start in a folder of the user's configuration
#: (not wherever the studio was started) and ask before replacing a file
SAVE_FOLDERS = {"preset_save": "presets", "layout_save": "layouts"}


def chosen_path(app_data: dict, extensions: tuple[str, ...] = ()) -> str:
    """The path a file dialog's OK names. dearpygui joins the folder shown and the File Name field
    whatever was typed there; a name typed as an absolute path (or from ``~``) is taken as it is.
    A name typed without an extension gets the dialog's first one (``tuning`` -> ``tuning.json``)."""
    name = str(app_data.get("file_name") or "").strip()
    typed = os.path.expanduser(name)
    if os.path.isabs(typed):
        path = typed
    elif name:
        path = os.path.join(str(app_data.get("current_path") or ""), name)
    else:
        path = str(app_data.get("file_path_name") or "")
    if path and extensions and not Path(path).suffix and not path.endswith(os.sep):
        path += extensions[0]
    return path


class FileDialogs:
    def __init__(self, dpg, handlers: dict[str, Callable[[str], object]],
                 report_error: Callable[[str, str], None] | None = None,
                 confirm: Callable[[str, str, str, Callable[[], object]], None] | None = None):
        missing = set(DIALOGS) - set(handlers)
        if missing:
            raise ValueError(f"no handler for the file dialogs {sorted(missing)}")
        self.dpg = dpg
        self.handlers = handlers
        self.report_error = report_error
        self.confirm = confirm     # (title, question, yes label, on yes): asks before a file is replaced

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
        """Show the dialog of ``kind``, starting in the folder of ``start_in`` when it exists (a saving
        dialog without one: its folder under the user's configuration, made if missing)."""
        if start_in is None and kind in SAVE_FOLDERS:
            from .layout_files import user_config_dir

            folder = user_config_dir() / SAVE_FOLDERS[kind]
            try:
                folder.mkdir(parents=True, exist_ok=True)
                start_in = str(folder / DIALOGS[kind][2])
            except OSError:     # an unwritable configuration: the dialog starts in the current folder
                pass
        if start_in:
            folder = Path(start_in).expanduser().parent
            self.dpg.configure_item(f"dlg_{kind}", default_path=str(folder if folder.is_dir() else Path.cwd()))
        self.dpg.configure_item(f"dlg_{kind}", show=True)

    @property
    def visible(self) -> bool:
        return any(self.dpg.is_item_shown(f"dlg_{k}") for k in DIALOGS)

    def _on_choice(self, sender, app_data, kind):
        path = chosen_path(app_data or {}, DIALOGS[kind][1])
        if not path:
            return
        if kind in SAVE_FOLDERS and self.confirm is not None and Path(path).is_file():
            self.confirm(DIALOGS[kind][0], f"{path} exists. Replace it?", "Replace",
                         lambda: self.handle(kind, path))
        else:
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
