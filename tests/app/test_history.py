"""The rewind buffer: ring addressing by tick number, gaps, series windows, agreement rate."""
from types import SimpleNamespace

import numpy as np
import pytest

from app.history import History, Tick, search_agreement


def snap(i: int, latent=True, searched=None, projected_frame=-1):
    """A stand-in for a DebugSnapshot with the fields the history reads."""
    pose = SimpleNamespace(global_positions=np.array([[i * 0.1, 0.0, -i * 0.2]] + [[0, 1, 0]] * 3, np.float32))
    return SimpleNamespace(
        best_cost=float(i), nn_cost=float(i) + 0.5, projected_cost=float(i) + 1.0, matched_frame=100 + i,
        nn_frame=100 + i + (i % 3), searched=(i % 6 == 0) if searched is None else searched,
        forced_search=False, transitioned=i % 12 == 0, simulation_velocity=np.array([1.0, 0.0, 0.0]),
        desired_velocity=np.array([0.0, 0.0, 2.0]), pose=pose,
        latent=np.full(4, float(i), np.float32) if latent else None, matched_latent=None,
        projected_frame=projected_frame,
        timings_us={"search": 12.0, "total": 100.0})


def tick(i: int, projected=None, **kw) -> Tick:
    """Tick ``i``; the LMM snapshot reports ``projected`` as its projected frame (-1: none this tick)."""
    return Tick(i, i / 60.0, {"mm": snap(i, latent=False),
                              "lmm": snap(i, projected_frame=-1 if projected is None else projected, **kw)})


def test_keeps_the_newest_ticks_and_addresses_them_by_number():
    h = History(10)
    assert h.latest() is None and h.oldest_tick == -1 and len(h) == 0
    for i in range(1, 26):
        h.append(tick(i))
    assert len(h) == 10
    assert h.newest_tick == 25 and h.oldest_tick == 16
    assert h.get(15) is None and h.get(16).tick == 16 and h.latest().tick == 25
    assert h.get(20).snapshots["mm"].matched_frame == 120
    assert h.clamp(3) == 16 and h.clamp(99) == 25 and h.clamp(18) == 18


def test_rejects_old_ticks_and_clears_gaps():
    h = History(8)
    h.append(tick(1))
    with pytest.raises(ValueError):
        h.append(tick(1))
    h.append(tick(5))  # 2..4 skipped
    assert h.get(2) is None and h.get(5) is not None
    w = h.window("lmm", "best_cost", 5, 5)
    assert np.isnan(w[1:4]).all() and w[0] == 1.0 and w[4] == 5.0


def test_series_windows_are_oldest_first_with_nan_outside():
    h = History(6)
    for i in range(1, 10):
        h.append(tick(i))
    w = h.window("lmm", "best_cost", 9, 8)  # ticks 2..9, only 4..9 held
    assert np.isnan(w[:2]).all()
    assert w[2:].tolist() == [4.0, 5.0, 6.0, 7.0, 8.0, 9.0]
    lat = h.window("lmm", "latent", 8, 3)
    assert lat.shape == (3, 4) and lat[:, 0].tolist() == [6.0, 7.0, 8.0]
    assert not h.has_series("mm", "latent")             # MM never reported a latent
    assert np.isnan(h.window("mm", "latent", 8, 3)).all()
    root = h.window("mm", "root_position", 9, 2)
    assert root.shape == (2, 3) and root[1, 0] == pytest.approx(0.9)
    assert h.window("lmm", "search_us", 9, 1)[0] == 12.0
    assert h.times(9, 2).tolist() == pytest.approx([8 / 60, 9 / 60])


def test_projected_frame_is_a_series_with_gaps_between_projections():
    h = History(5)
    for i in range(1, 5):
        h.append(tick(i, projected=200 + i if i % 2 == 0 else -1))
    w = h.window("lmm", "projected_frame", 4, 4)
    assert np.isnan(w[0]) and w[1] == 202 and np.isnan(w[2]) and w[3] == 204
    assert np.isnan(h.window("mm", "projected_frame", 4, 4)).all()
    t = tick(5)
    t.extra["projected_frame:lmm"] = 999          # tick.extra is never read as a series
    h.append(t)
    assert np.isnan(h.window("lmm", "projected_frame", 5, 1)[0])


def test_agreement_rate_counts_searches_within_tolerance():
    h = History(120)
    for i in range(1, 61):
        h.append(tick(i, projected=100 + i))     # the nn frame is 100 + i + (i % 3)
    rate0, n = search_agreement(h, "lmm", 60, 60, tolerance_frames=0)
    searches = [i for i in range(1, 61) if i % 6 == 0]
    assert n == len(searches)
    assert rate0 == pytest.approx(np.mean([(i % 3) == 0 for i in searches]))
    rate2, _ = search_agreement(h, "lmm", 60, 60, tolerance_frames=2)
    assert rate2 == 1.0
    assert search_agreement(h, "mm", 60, 60)[1] == 0   # no projected frames for MM


def test_clear_and_capacity_checks():
    with pytest.raises(ValueError):
        History(0)
    h = History(4)
    h.append(tick(1))
    h.clear()
    assert len(h) == 0 and h.newest_tick == -1 and h.latest() is None


def test_oldest_tick_follows_every_append_and_clear():
    """oldest_tick is kept between appends (panels ask every frame): each append that drops a tick, a gap
    and clear() show in the next answer."""
    h = History(4)
    h.append(tick(1))
    assert h.oldest_tick == 1
    for i in range(2, 5):
        h.append(tick(i))
        assert h.oldest_tick == 1
    h.append(tick(5))                  # the ring is full: tick 1 drops out
    assert h.oldest_tick == 2
    assert h.oldest_tick == 2          # asked again with nothing new: the same
    h.append(tick(7))                  # a gap: 6 is never held, 2 and 3 drop out
    assert h.oldest_tick == 4
    h.clear()
    assert h.oldest_tick == -1
    h.append(tick(9))
    assert h.oldest_tick == 9
