"""The playback state machine without a display: live, pause, scrub, step, and ticks due per frame."""
from app.history import History, Tick
from app.playback import MAX_TICKS_PER_FRAME, Playback

DT = 1 / 60


def _history(n_ticks: int, capacity: int = 100) -> History:
    h = History(capacity)
    for i in range(1, n_ticks + 1):
        h.append(Tick(i, i * DT, {}))
    return h


def test_live_shows_the_newest_tick_and_runs():
    h = _history(10)
    p = Playback(h, DT, fixed_step=True)
    assert p.live and not p.paused and p.mode == "LIVE"
    assert p.displayed_tick().tick == 10 and p.ticks_due(0.5) == 1
    h.append(Tick(11, 11 * DT, {}))
    assert p.displayed_tick().tick == 11


def test_pause_holds_the_tick_and_simulates_nothing():
    h = _history(10)
    p = Playback(h, DT, fixed_step=True)
    p.toggle_pause()
    assert p.paused and not p.live and p.mode == "PAUSED" and p.scrub_tick == 10
    assert p.ticks_due(1.0) == 0
    p.toggle_pause()
    assert p.live and p.ticks_due(0.0) == 1


def test_scrub_and_step_back_and_forward():
    h = _history(50)
    p = Playback(h, DT)
    p.scrub_to(20)
    assert p.paused and p.displayed_tick().tick == 20
    p.scrub_to(-100)
    assert p.displayed_tick().tick == 1                     # clamped to the oldest held
    p.step(5)
    assert p.displayed_tick().tick == 6 and p.ticks_due(0.1) == 0
    p.scrub_to(50)
    p.step(3)                                               # past the newest: simulate 3 new ticks
    assert p.scrub_tick is None and p.ticks_due(0.0) == 3 and p.ticks_due(0.0) == 0
    p.go_live()
    assert p.live


def test_step_from_live_pauses_first():
    h = _history(30)
    p = Playback(h, DT)
    p.step(-1)
    assert p.paused and p.displayed_tick().tick == 29


def test_scrubbed_tick_that_falls_out_of_the_buffer_is_clamped():
    h = _history(10, capacity=10)
    p = Playback(h, DT)
    p.scrub_to(1)
    for i in range(11, 16):
        h.append(Tick(i, i * DT, {}))
    assert p.displayed_tick().tick == h.oldest_tick == 6


def test_free_running_ticks_follow_the_clock():
    p = Playback(_history(1), DT)
    assert p.ticks_due(0.0) == 0
    assert p.ticks_due(DT * 2.5) == 2
    assert p.ticks_due(DT * 0.6) == 1                       # the half tick left over carried on
    assert p.ticks_due(10.0) == MAX_TICKS_PER_FRAME         # a stall: capped, not a spiral


def test_empty_history():
    p = Playback(History(10), DT)
    assert p.displayed_tick() is None
    p.scrub_to(5)
    assert p.live
    p.pause()
    assert p.scrub_tick is None and p.paused
