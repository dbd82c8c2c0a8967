"""What the tick worker prepares for the next frame (app.prepared): when a result is used, when the
GUI thread works it out itself, and the check that compares the two."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from app.history import History
from app.panels.base import Panel, View
from app.prepared import Preparer, same


class Counting(Panel):
    """A panel whose result is its setting and the tick number (or, broken, a random number)."""
    key = "stats"

    def __init__(self, broken=False):
        self.setting, self.broken, self.calls = 1, broken, 0

    def prepare_key(self, view):
        return (self.setting,)

    def prepare(self, view):
        self.calls += 1
        value = np.random.random() if self.broken else float(view.tick.tick)
        return {"x": np.array([value, np.nan]), "setting": self.setting}


class Plain(Panel):
    key = "menu"

    def __init__(self):
        pass


def _view(tick, frame, **kw):
    return View(tick=tick, history=History(10), live=kw.pop("live", True), paused=False, inspected="mm",
                frame=frame, **kw)


def test_same_is_deep_equality_with_nan():
    a = {"x": np.array([1.0, np.nan]), "y": [1, (2.0, "a")], "z": SimpleNamespace(v=np.zeros(2))}
    b = {"x": np.array([1.0, np.nan]), "y": [1, (2.0, "a")], "z": SimpleNamespace(v=np.zeros(2))}
    assert same(a, b) and same(float("nan"), float("nan"))
    assert not same(np.zeros(2, np.float32), np.zeros(2))                  # dtype
    assert not same(np.zeros(2), np.zeros(3)) and not same(np.zeros(2), [0.0, 0.0])
    assert not same([1, 2], (1, 2)) and not same({"a": 1}, {"a": 1, "b": 2})
    b["z"].v[1] = 1e-12
    assert not same(a, b)


def test_a_prepared_result_is_used_only_for_the_frame_it_was_made_for():
    panel = Counting()
    prep = Preparer({"stats": panel, "menu": Plain()})
    assert list(prep.panels) == ["stats"]                  # only panels that override prepare
    tick = SimpleNamespace(tick=7)
    view = _view(tick, frame=3)
    job = prep.job(view, {"stats"}, next_frame=4)
    made = job(tick)                                       # on the worker, after stepping tick 7
    assert made.frame == 4 and made.parts["stats"][1]["x"][0] == 7.0
    prep.receive(made)
    nxt = _view(tick, frame=4)
    assert same(prep.result("stats", nxt), made.parts["stats"][1]) and prep.used["stats"] == 1
    assert prep.result("menu", nxt) is None and prep.inline["menu"] == 0       # not a preparing panel
    # a different frame, tick, view or setting: the panel works it out itself
    for other in (_view(tick, frame=5), _view(SimpleNamespace(tick=7), frame=4),
                  _view(tick, frame=4, problems={"lmm": "off"}), _view(tick, frame=4, latent_status="x")):
        assert prep.result("stats", other) is None
    panel.setting = 2
    assert prep.result("stats", nxt) is None
    assert prep.inline["stats"] == 5 and prep.used["stats"] == 1
    # nothing is prepared when the next frame will not show the newest tick, or for hidden panels
    assert prep.job(_view(tick, frame=3, live=False), {"stats"}, 4) is None
    assert prep.job(view, set(), 4)(tick).parts == {}


def test_the_check_finds_a_result_that_differs_from_the_gui_threads(monkeypatch):
    monkeypatch.setenv("LMM_STUDIO_CHECK_PREPARED", "1")
    tick = SimpleNamespace(tick=1)
    for broken, expected in ((False, []), (True, [("stats", 2)])):
        panel = Counting(broken=broken)
        prep = Preparer({"stats": panel})
        prep.receive(prep.job(_view(tick, frame=1), {"stats"}, 2)(tick))
        assert prep.result("stats", _view(tick, frame=2)) is not None
        assert prep.mismatches == expected and panel.calls == 2
        assert prep.state()["checked"] and prep.state()["mismatches"] == [list(m) for m in expected]


def test_the_replaced_results_are_freed_on_the_tick_worker():
    """Freeing a frame's prepared numbers (thousands of small objects) took 0.1 ms of the GUI thread's
    frame: the studio hands what ``receive`` replaced to the worker, which drops it while the GUI thread
    draws."""
    import threading

    from app.tick_worker import TickWorker
    from lmm.controller import InputState

    prep = Preparer({"stats": Counting()})
    first, second = object(), object()
    assert prep.receive(first) is None and prep.receive(second) is first

    freed = []

    class Heavy:
        def __del__(self):
            freed.append(threading.current_thread().name)

    stepped = []
    session = SimpleNamespace(step=lambda inp: stepped.append(inp) or SimpleNamespace(snapshots={}), step_ms={},
                              deliver_reports=lambda: None)
    worker = TickWorker(session)
    try:
        worker.submit([InputState()], release=Heavy())
        assert len(worker.wait()) == 1 and len(stepped) == 1
        assert freed == ["studio-ticks"]
        worker.submit([], release=Heavy())      # nothing to step (paused): freed by the caller, at once
        assert freed == ["studio-ticks", threading.current_thread().name]
    finally:
        worker.close()


def test_a_reopened_sessions_frames_are_worked_out_each_time_never_kept():
    """A reopened session's history fills around each pick while its newest tick stays the session's
    last, so a result kept from an earlier paused frame could be stale: each frame works it out (and the
    worker prepares nothing for it, since its ticks are not the session's)."""
    panel = Counting()
    prep = Preparer({"stats": panel})
    tick = SimpleNamespace(tick=3)
    history = History(10)
    history.is_session = True
    paused = View(tick=tick, history=history, live=False, paused=True, inspected="mm", frame=1)
    assert paused.mode == "SESSION"
    for frame in range(1, 4):
        assert prep.result("stats", View(tick=tick, history=history, live=False, paused=True, inspected="mm",
                                         frame=frame)) is None
    assert prep.inline["stats"] == 3 and prep.kept.get("stats", 0) == 0
    playing = View(tick=tick, history=history, live=True, paused=False, inspected="mm", frame=4)
    assert prep.job(playing, {"stats"}, 5) is None
    # the same paused frames outside a session keep the first result
    live_history = View(tick=tick, history=History(10), live=False, paused=True, inspected="mm", frame=5)
    first = prep.result("stats", live_history)
    assert first is not None and prep.result("stats", live_history) is first and prep.kept["stats"] == 1
