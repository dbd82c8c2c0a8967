"""Undo and redo of tuning changes (app/undo.py), without a display."""
from __future__ import annotations

from app.input.keyboard import shortcut_modifiers
from app.undo import DRAG_GAP_S, TuningUndo
from lmm.tuning import Tuning


def _exactly(a: dict, b: dict) -> bool:
    """Every field equal, and of the same type (1 is not 1.0, False is not 0)."""
    def typed(v):
        return {k: (type(x), x) for k, x in v.items()} if isinstance(v, dict) else (type(v), v)
    return a.keys() == b.keys() and all(typed(a[k]) == typed(b[k]) for k in a)


def test_five_changes_undone_and_redone_exactly():
    t = Tuning()
    t.name_database_entries({"hip_velocity": 1.0}, ["walk", "crouch"])
    now = [0.0]
    undo = TuningUndo(t, clock=lambda: now[0])
    start = t.to_dict()
    changes = [("run_forward_speed_m_s", 1.25, None), ("top_k", 12, None),
               ("feature_weights", 0.3, "hip_velocity"), ("tag_excluded", True, "crouch"), ("tag_bias", -0.5, "walk")]
    for field, value, channel in changes:
        t.set(field, value, channel)
        undo.end_frame()
        now[0] += 1.0
    end = t.to_dict()
    assert not _exactly(start, end) and undo.state() == {"undo": 5, "redo": 0}
    for _ in range(5):
        assert undo.undo()
    assert not undo.undo() and _exactly(t.to_dict(), start)
    for _ in range(5):
        assert undo.redo()
    assert not undo.redo() and _exactly(t.to_dict(), end)
    # undo writes are announced like a slider's (the session log and the widgets see them)
    seen = []
    t.events.connect(seen.append)
    undo.undo()
    assert [(c.field, c.channel, c.old, c.new) for c in seen] == [("tag_bias", "walk", -0.5, 0.0)]
    # a new change clears what could be redone
    t.set("run_forward_speed_m_s", 2.0)
    assert undo.state()["redo"] == 0 and not undo.redo()


def test_a_drag_is_one_step_and_one_frame_is_one_step():
    t = Tuning()
    now = [0.0]
    undo = TuningUndo(t, clock=lambda: now[0])
    before = t.run_forward_speed_m_s
    for v in (3.0, 2.5, 2.0, 1.5):             # one slider, frame after frame
        t.set("run_forward_speed_m_s", v)
        undo.end_frame()
        now[0] += DRAG_GAP_S / 4
    now[0] += 1.0
    t.set("walk_forward_speed_m_s", 1.0)
    undo.end_frame()                           # (a step of its own)
    t.reset_group("speeds")                    # many fields in one frame (a group reset)
    undo.end_frame()
    assert len(undo.undo_steps) == 3 and len(undo.undo_steps[-1]) == 2
    undo.undo()
    assert t.run_forward_speed_m_s == 1.5 and t.walk_forward_speed_m_s == 1.0
    undo.undo()
    undo.undo()
    assert t.run_forward_speed_m_s == before and t.walk_forward_speed_m_s == Tuning().walk_forward_speed_m_s
    now[0] += 10
    t.set("run_forward_speed_m_s", 3.0)
    undo.end_frame()
    now[0] += 2 * DRAG_GAP_S                  # the same slider again, later: another step
    t.set("run_forward_speed_m_s", 2.0)
    assert len(undo.undo_steps) == 2


def test_a_slow_drag_with_the_mouse_held_is_one_step():
    """A drag at a few frames a second (changes further apart than DRAG_GAP_S) is still one step while the
    mouse button stays down; released between them, they are separate steps."""
    for held, steps in ((True, 1), (False, 3)):
        t = Tuning()
        now = [0.0]
        undo = TuningUndo(t, clock=lambda: now[0])
        for v in (3.0, 2.5, 2.0):
            t.set("run_forward_speed_m_s", v)
            undo.end_frame(mouse_held=held)
            now[0] += 2 * DRAG_GAP_S
        assert len(undo.undo_steps) == steps
        undo.end_frame(mouse_held=False)
        now[0] += 2 * DRAG_GAP_S
        t.set("run_forward_speed_m_s", 1.0)          # released: the next change is a step of its own
        assert len(undo.undo_steps) == steps + 1


def test_chord_shortcuts_need_their_modifiers():
    assert shortcut_modifiers("Ctrl+Z") == (True, False) and shortcut_modifiers("Ctrl+Shift+Z") == (True, True)
    assert shortcut_modifiers("Space") is None and shortcut_modifiers(",") is None and shortcut_modifiers("F") is None
