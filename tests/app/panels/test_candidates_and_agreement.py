"""The Search Candidates rows and colours, frame names, and the Nearest Neighbour vs Projector agreement."""
import numpy as np
import pytest
from app.panels.common import cost_color
from app.panels.candidates import candidate_rows, column_fractions, sort_rows, split_field, what_if_fields
from app.panels.search import frame_label, rolling_agreement
from lmm.controller import Candidates


def _rows(totals):
    return [{"total": float(v), "channels": [float(v)]} for v in totals]


def test_candidate_rows_sort_and_colour_fractions(dbf):
    db, _ = dbf
    c = Candidates(frames=np.array([10, 2000, 30]), costs=np.array([1.0, 3.0, 2.0], np.float32),
                   channel_costs=np.array([[0.5, 0.5], [2.0, 1.0], [0.1, 1.9]], np.float32),
                   bias=np.zeros(3, np.float32), channel_names=["a", "b"])
    rows = candidate_rows(c, db)
    assert [r["rank"] for r in rows] == [1, 2, 3] and rows[1]["frame"] == 2000
    assert rows[0]["clip"] != "-" and rows[0]["t"] >= 0
    for r in rows:   # the candidates show the tags of their range
        assert r["tags"] == ", ".join(db.tags_of(r["frame"])) and r["tags"]
    assert [r["frame"] for r in sort_rows(rows, "total", descending=True)] == [2000, 30, 10]
    assert [r["frame"] for r in sort_rows(rows, "ch1")] == [10, 2000, 30]
    assert [r["frame"] for r in sort_rows(rows, "frame", descending=True)] == [2000, 30, 10]
    assert column_fractions(rows, "total") == [0.0, 1.0, 0.5]
    assert column_fractions(rows, "ch0")[2] == 0.0
    assert candidate_rows(None) == []
    green, red = cost_color(0.0), cost_color(1.0)
    assert green[1] > green[0] and red[0] > red[1]


def test_frame_label_names_the_clip(dbf):
    db, _ = dbf
    name, t = frame_label(db, int(db.range_starts[1]) + 60)
    assert "mirror" in name and t == pytest.approx(1.0)
    assert frame_label(db, -1)[0] == "-"


def test_rolling_agreement():
    searched = np.array([1, 0, 1, 0, 1, 1], float)
    nn = np.array([5, 5, 7, 7, 9, 9], float)
    got = np.array([5, np.nan, 8, np.nan, 9, 20], float)
    r = rolling_agreement(searched, nn, got, window=10, tolerance=0)
    assert r[0] == 1.0 and r[2] == 0.5 and r[4] == pytest.approx(2 / 3) and r[5] == 0.5
    assert rolling_agreement(searched, nn, got, window=10, tolerance=1)[2] == 1.0
    assert np.isnan(rolling_agreement(np.zeros(3), nn[:3], got[:3], 5)).all()


def test_rolling_agreement_is_the_windowed_rate_and_matches_agreement():
    from app.history import agreement
    from app.panels.search import search_masks

    rng = np.random.default_rng(11)
    for window in (0, 1, 7, 40, 500):
        searched = (rng.random(300) < 0.3).astype(float)
        nn = rng.integers(-1, 50, 300).astype(float)
        got = nn + rng.integers(-2, 3, 300)
        nn[rng.random(300) < 0.05] = np.nan
        got[rng.random(300) < 0.05] = np.inf
        r = rolling_agreement(searched, nn, got, window, tolerance=1)
        for i in range(300):      # each tick by itself: the ticks (i - window, i]
            lo = max(i - window + 1, 0)
            rate, k = agreement(searched[lo:i + 1], nn[lo:i + 1], got[lo:i + 1], 1)
            assert (np.isnan(r[i]) and k == 0) if k == 0 or window == 0 else r[i] == rate
        s, agree = search_masks(searched, nn, got, 1)
        rate, k = agreement(searched, nn, got, 1)
        assert k == int(s.sum()) and rate == int(agree.sum()) / k


def test_equal_costs_get_equal_colours():
    # values that read the same (3 decimals) are the same colour; all equal: all green
    same = _rows([1.25, 1.25 + 1e-7, 1.25 + 2e-7, 1.25])
    assert column_fractions(same, "total") == [0.0] * 4
    assert len({cost_color(f) for f in column_fractions(same, "total")}) == 1
    assert cost_color(0.0)[1] > cost_color(0.0)[0]                       # green
    spread = _rows([1.0, 2.0, 2.0, 3.0])
    f = column_fractions(spread, "total")
    assert f == [0.0, 0.5, 0.5, 1.0] and cost_color(f[1]) == cost_color(f[2])
    assert column_fractions(_rows([1.0, float("nan")]), "ch0") == [0.0, 1.0]


def test_what_if_entries_name_tuning_fields_and_entries():
    """Every entry the what-if combo offers is a field (and entry) the scratch tuning can be set by."""
    from lmm.tuning import Tuning

    tuning = Tuning()
    entries = what_if_fields(list(tuning.feature_weights), tuning)
    assert "feature_weights.hip_velocity" in entries and "transition_cost" in entries
    assert split_field("feature_weights.hip_velocity") == ("feature_weights", "hip_velocity")
    assert split_field("transition_cost") == ("transition_cost", None)
    for entry in entries:
        field, channel = split_field(entry)
        scratch = tuning.copy()
        scratch.set(field, 0.5 if field != "exclude_current_window_frames" else 7, channel)
        got = getattr(scratch, field) if channel is None else getattr(scratch, field)[channel]
        assert got == (0.5 if field != "exclude_current_window_frames" else 7), entry
