"""Undo and redo of tuning changes (Ctrl+Z / Ctrl+Shift+Z, Edit menu), built on the tuning's change events
(:class:`lmm.tuning.TuningChange`: field, channel, old, new), the same events a session file records.

A *step* is what one undo takes back: every change made in one studio frame (a preset load, a group reset,
a typed value), and a slider drag as a whole (changes of one field that follow each other within
:data:`DRAG_GAP_S`, frame after frame, or any time apart while the mouse button stays down: a slow drag
at a few frames a second is still one drag). Undo puts the old values back in reverse order, redo the new ones in
order, by plain assignment: the tuning ends exactly as it was (values and types), and the writes are
announced like any other, so the sliders, the controllers and a session being recorded see them. A new
change clears what could be redone.
"""
from __future__ import annotations

import time

#: changes of one field this close together (seconds) are one drag, hence one step
DRAG_GAP_S = 0.5
#: steps kept (the oldest is forgotten first)
MAX_STEPS = 500


class TuningUndo:
    def __init__(self, tuning, clock=time.monotonic):
        self.tuning = tuning
        self.clock = clock
        self.undo_steps: list[list] = []     # each a list of TuningChange, oldest first
        self.redo_steps: list[list] = []
        self._open = False                  # the newest step takes this frame's changes
        self._last = (None, -1.0)           # (field, channel) of the newest change, and when it came
        self._applying = False
        self._held = False                  # the mouse button was down at the end of the last frame
        tuning.events.connect(self._on_change)

    def _on_change(self, change) -> None:
        if self._applying:
            return
        key, now = (change.field, change.channel), self.clock()
        step = self.undo_steps[-1] if self.undo_steps else None
        drag = (step is not None and self._last[0] == key and (now - self._last[1] < DRAG_GAP_S or self._held)
                and all((c.field, c.channel) == key for c in step))
        if step is not None and (self._open or drag):
            step.append(change)
        else:
            self.undo_steps.append([change])
            del self.undo_steps[:-MAX_STEPS]
        self._open = True
        self._last = (key, now)
        self.redo_steps.clear()

    def end_frame(self, mouse_held: bool = False) -> None:
        """The studio's frame is over: the next change starts a new step (unless it continues a drag;
        ``mouse_held``: the mouse button is down, so a change of the same field still is one)."""
        self._open = False
        self._held = bool(mouse_held)

    def undo(self) -> bool:
        """Take back the newest step; False when there is none."""
        if not self.undo_steps:
            return False
        step = self.undo_steps.pop()
        self._apply([(c.field, c.channel, c.old) for c in reversed(step)])
        self.redo_steps.append(step)
        return True

    def redo(self) -> bool:
        """Make the newest undone step again; False when there is none."""
        if not self.redo_steps:
            return False
        step = self.redo_steps.pop()
        self._apply([(c.field, c.channel, c.new) for c in step])
        self.undo_steps.append(step)
        return True

    def _apply(self, writes) -> None:
        self._applying = True
        self._open, self._last, self._held = False, (None, -1.0), False
        try:
            for field, channel, value in writes:
                if channel is None:
                    setattr(self.tuning, field, value)
                elif value is None:                       # the entry did not exist (or was removed)
                    getattr(self.tuning, field).pop(channel, None)
                else:
                    getattr(self.tuning, field)[channel] = value
        finally:
            self._applying = False

    def state(self) -> dict:
        return {"undo": len(self.undo_steps), "redo": len(self.redo_steps)}
