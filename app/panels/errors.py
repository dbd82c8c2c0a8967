"""Messages in a dialog: errors (a bad BVH, weights, preset, input or layout file; reported here and on
stderr, and the studio keeps running) and information (help). Several queue up; OK shows the next.
The dialog's title says which: "Error" for errors, the message's own title for information.

The dialog is an ordinary window kept in front, not a modal popup: a modal opened from a file dialog's
callback (itself a closing modal) was never drawn, and the keys waited behind it. It never takes the
keys: the character still moves while a message is shown (:meth:`ErrorDialog.keep_shown` re-opens it
each frame while messages wait)."""
from __future__ import annotations

import sys
import time

ERROR_WINDOW = 10090


class ErrorDialog:
    window = ERROR_WINDOW

    def __init__(self, dpg):
        self.dpg = dpg
        self.shown: list[dict] = []     # every error reported this session (also for the test dump)
        self.queue: list[dict] = []
        self.built = False

    def build(self) -> None:
        dpg = self.dpg
        with dpg.window(tag=ERROR_WINDOW, label="Error", show=False, no_docking=True, no_collapse=True,
                        width=560, height=190, no_saved_settings=True, on_close=self.dismiss):
            dpg.add_text("", tag="err_title", color=(255, 140, 120))
            dpg.add_text("", tag="err_message", wrap=520)
            dpg.add_spacer(height=6)
            with dpg.group(horizontal=True):
                dpg.add_button(label="OK", width=80, tag="err_ok", callback=self.dismiss)
                dpg.add_button(label="Yes", width=80, tag="err_yes", callback=self.accept, show=False)
                dpg.add_text("", tag="err_more", color=(150, 150, 160))
        self.built = True
        self._present()

    def show(self, title: str, message: str) -> None:
        """Report an error (counted in :attr:`shown` and printed on stderr)."""
        entry = {"title": str(title), "message": str(message), "time": time.time(), "error": True}
        self.shown.append(entry)
        print(f"lmm-studio: {title}: {message}", file=sys.stderr)
        self._enqueue(entry)

    def inform(self, title: str, message: str) -> None:
        """Show information (help, notices) in the same dialog, titled ``title``; not an error."""
        self._enqueue({"title": str(title), "message": str(message), "time": time.time(), "error": False})

    def ask(self, title: str, question: str, yes_label: str, on_yes) -> None:
        """Ask ``question`` (e.g. before replacing a file): ``yes_label`` runs ``on_yes``, Cancel nothing."""
        self._enqueue({"title": str(title), "message": str(question), "time": time.time(), "error": False,
                       "on_yes": on_yes, "yes": str(yes_label)})

    def accept(self, *args) -> None:
        """The question shown is answered yes: its action runs (an error it reports queues after it)."""
        entry = self.queue.pop(0) if self.queue else {}
        if entry.get("on_yes") is not None:
            entry["on_yes"]()
        self._present()

    def _enqueue(self, entry: dict) -> None:
        self.queue.append(entry)
        if self.built:
            self._present()

    def _present(self) -> None:
        dpg = self.dpg
        if not self.queue:
            dpg.configure_item(ERROR_WINDOW, show=False)
            return
        e = self.queue[0]
        dpg.configure_item(ERROR_WINDOW, label=("Error" if e["error"] else e["title"]))
        dpg.configure_item("err_title", show=e["error"])
        dpg.set_value("err_title", e["title"])
        dpg.set_value("err_message", e["message"])
        asking = e.get("on_yes") is not None
        dpg.configure_item("err_yes", show=asking, label=e.get("yes", "Yes"))
        dpg.configure_item("err_ok", label="Cancel" if asking else "OK")
        dpg.set_value("err_more", f"{len(self.queue) - 1} more" if len(self.queue) > 1 else "")
        try:
            vw, vh = dpg.get_viewport_client_width() or 1600, dpg.get_viewport_client_height() or 900
        except Exception:  # no viewport yet (errors found while starting up)
            vw, vh = 1600, 900
        dpg.configure_item(ERROR_WINDOW, show=True, pos=(max(vw // 2 - 280, 0), max(vh // 2 - 95, 0)))
        dpg.focus_item(ERROR_WINDOW)

    def keep_shown(self) -> None:
        """Called every frame: a waiting message whose window is not shown (closed by its x, or an
        open that dearpygui dropped) is shown again, in front."""
        if self.queue and self.built and not self.dpg.is_item_shown(ERROR_WINDOW):
            self._present()

    def dismiss(self, *args) -> None:
        if self.queue:
            self.queue.pop(0)
        self._present()

    @property
    def visible(self) -> bool:
        return bool(self.queue)

    @property
    def title(self) -> str:
        """The title the dialog shows now ("" when hidden)."""
        if not self.queue:
            return ""
        e = self.queue[0]
        return "Error" if e["error"] else e["title"]

    def last(self) -> dict | None:
        return self.shown[-1] if self.shown else None
