"""The Stats panel's frame times: medians and percentiles as numpy's, series kept per frame, controller time per
tick."""
import numpy as np
from app.frame_times import per_tick_ms
from app.frame_times import FrameTimes


def test_frame_time_median_and_percentile_are_numpys():
    from app.frame_times import median, percentile

    rng = np.random.default_rng(7)
    for i in range(400):
        a = rng.exponential(20.0, int(rng.integers(1, 260)))
        if i % 4 == 0:
            a = np.round(a)                                     # ties
        for q in (0.0, 50.0, 95.0, 100.0, float(rng.uniform(0, 100))):
            assert percentile(a, q) == float(np.percentile(a, q))
        assert median(a) == float(np.median(a))
    a[3] = np.nan
    assert np.isnan(median(a)) and np.isnan(percentile(a, 95))
    ft = FrameTimes(n=5)
    assert np.isnan(ft.percentile(95))
    for ms in (10, 20, 30, 40, 50, 60):                         # 10 has left the window
        ft.add(ms, {"ui": ms / 2})
    assert ft.percentile(95) == float(np.percentile([20, 30, 40, 50, 60], 95))
    assert ft.percentile(50, "ui") == 20.0


def test_frame_time_series_are_kept_until_the_next_frame():
    """series() hands out one array per part until the next add (the Stats panel, its percentile and
    the medians share it); the next frame's time is in the next answer."""
    ft = FrameTimes(n=3)
    for ms in (10, 20, 30):
        ft.add(ms, {"mm": ms / 10})
    a = ft.series()
    assert a.tolist() == [10.0, 20.0, 30.0] and ft.series() is a        # unchanged: not rebuilt
    assert ft.series("mm").tolist() == [1.0, 2.0, 3.0]
    assert ft.percentile(100) == 30.0 and ft.median() == 20.0
    ft.add(40, {"ui": 5.0})                                           # a frame without an MM step
    assert ft.series().tolist() == [20.0, 30.0, 40.0] and ft.series() is not a
    assert ft.series("mm").tolist() == [1.0, 2.0, 3.0] and ft.series("ui").tolist() == [5.0]
    assert ft.percentile(100) == 40.0 and ft.median() == 30.0
    assert ft.series("nothing").tolist() == []
    for ms in (50, 60, 70, 80):                                      # round the window again
        ft.add(ms, {"mm": ms / 10})
    assert ft.series().tolist() == [60.0, 70.0, 80.0] and ft.series("mm").tolist() == [6.0, 7.0, 8.0]


def test_controller_time_is_per_tick_and_absent_without_ticks():
    assert per_tick_ms([], ["mm"]) == {}                              # no tick finished: no zero added
    finished = [(None, {"mm": 2.0, "lmm": 1.0}), (None, {"mm": 4.0, "lmm": 3.0})]
    assert per_tick_ms(finished, ["mm", "lmm"]) == {"mm": 3.0, "lmm": 2.0}
    ft = FrameTimes()
    for i in range(10):   # a frame rate above the tick rate: half the frames finish no tick
        ft.add(5.0, per_tick_ms(finished if i % 2 else [], ["mm"]))
    assert ft.median("mm") == 3.0
