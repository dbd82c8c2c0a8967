"""Input logs (CSV), the streaming writer and the built-in scenarios."""
from pathlib import Path

import numpy as np
import pytest

from lmm.controller import InputState
from lmm.data.inputs import (BUILTIN_SCENARIOS, InputCsvWriter, InputError, InputLog, builtin, builtin_names,
                        load_input_csv, open_input, save_input_csv)

CORPUS = Path(__file__).resolve().parents[2] / "input_corpus"

# file -> (line, column) the error must name
BROKEN = {
    "missing_column.csv": (1, 7),
    "nan_value.csv": (3, 2),
    "time_backwards.csv": (5, 1),
    "non_numeric.csv": (3, 3),
    "bad_flag.csv": (3, 6),
    "stick_out_of_range.csv": (3, 3),
    "short_row.csv": (3, 6),
}


@pytest.mark.parametrize("name", sorted(BROKEN))
def test_broken_logs_name_file_line_and_column(name):
    line, column = BROKEN[name]
    with pytest.raises(InputError) as e:
        load_input_csv(CORPUS / name)
    msg = str(e.value)
    assert name in msg and f"line {line}" in msg and f"column {column}" in msg, msg
    assert e.value.line == line and e.value.column == column


def test_valid_log_rows_are_held_until_the_next():
    log = load_input_csv(CORPUS / "valid_crlf.csv")
    assert log.n_rows == 3 and log.duration == 2.0
    assert log.at(-1.0) == log.at(0.0) == InputState(0.0, 1.0, 0.0, 0.0, False, False, 0.0)
    assert log.at(0.2499).left_x == 0.0
    assert log.at(0.25).left_x == 0.5 and log.at(0.25).walk
    assert log.at(1.99).left_x == 0.5
    assert log.at(100.0).left_y == 0.0


def test_missing_file_and_empty_file(tmp_path):
    with pytest.raises(InputError, match="no such input file"):
        load_input_csv(tmp_path / "nope.csv")
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(InputError, match="line 1"):
        load_input_csv(tmp_path / "empty.csv")
    (tmp_path / "header_only.csv").write_text("time,left_x,left_y,right_x,right_y,walk,strafe\n")
    with pytest.raises(InputError, match="line 2"):
        load_input_csv(tmp_path / "header_only.csv")


def test_save_and_load_is_exact(tmp_path):
    log = builtin("random:7", 20.0)
    p = tmp_path / "log.csv"
    save_input_csv(p, log)
    back = load_input_csv(p)
    for name in ("times", "left_x", "left_y", "right_x", "right_y", "walk", "strafe", "camera_azimuth"):
        assert np.array_equal(getattr(back, name), getattr(log, name)), name


def test_streaming_writer_replays_the_same_inputs(tmp_path):
    log = builtin("zigzag", 6.0)
    p = tmp_path / "stream.csv"
    dt = 1 / 60
    with InputCsvWriter(p, flush_interval_s=0.0) as w:
        for i in range(360):
            w.write(i * dt, log.at(i * dt))
        # flushed as it goes: already a valid log before close
        assert load_input_csv(p).n_rows == w.rows
    back = load_input_csv(p)
    assert back.n_rows < 360  # only changes are written
    for i in range(360):
        assert back.at(i * dt) == log.at(i * dt)


@pytest.mark.parametrize("name", builtin_names((1, 2)))
def test_builtins_are_deterministic_and_in_range(name):
    a, b = builtin(name, 30.0), builtin(name, 30.0)
    assert np.array_equal(a.times, b.times) and np.array_equal(a.left_x, b.left_x)
    assert a.duration >= 29.0
    for arr in (a.left_x, a.left_y, a.right_x, a.right_y):
        assert np.isfinite(arr).all() and np.abs(arr).max() <= 1.0 + 1e-12
    assert np.all(np.diff(a.times) >= 0)
    assert np.hypot(a.left_x, a.left_y).max() > 0.5  # it moves


def test_random_prefix_does_not_depend_on_length():
    short, long = builtin("random:3", 10.0), builtin("random:3", 100.0)
    for t in np.linspace(0, 10, 101):
        assert short.at(t) == long.at(t)
    assert not np.array_equal(builtin("random:4", 10.0).left_x[:5], short.left_x[:5])


def test_builtin_specs_and_errors():
    assert "random:SEED" in BUILTIN_SCENARIOS and {"circle", "zigzag", "stop-and-go", "strafe"} <= set(BUILTIN_SCENARIOS)
    assert isinstance(open_input("builtin:circle", 5.0), InputLog)
    assert open_input(str(CORPUS / "valid_crlf.csv")).n_rows == 3
    with pytest.raises(InputError, match="unknown built-in input 'nope'"):
        open_input("builtin:nope")
    with pytest.raises(InputError, match="seed"):
        open_input("builtin:random:abc")


HEADER = "time,left_x,left_y,right_x,right_y,walk,strafe,camera_azimuth\n"


@pytest.mark.parametrize("row, column, words", [
    ("1e308,0,0,0,0,0,0,0", 1, "outside [0, 86400]"),
    ("86400.5,0,0,0,0,0,0,0", 1, "MAX_INPUT_SECONDS"),
    ("-1,0,0,0,0,0,0,0", 1, "outside [0, 86400]"),
    ("inf,0,0,0,0,0,0,0", 1, "finite"),
    ("1,0,0,0,0,0,0,1e300", 8, "MAX_CAMERA_AZIMUTH_RAD"),
])
def test_times_and_magnitudes_beyond_what_a_run_can_do_are_refused(tmp_path, row, column, words):
    p = tmp_path / "log.csv"
    p.write_text(HEADER + "0,0,0,0,0,0,0,0\n" + row + "\n")
    with pytest.raises(InputError) as e:
        load_input_csv(p)
    assert e.value.line == 3 and e.value.column == column and words in str(e.value) and str(p) in str(e.value)
    from lmm.errors import InputError as BaseInputError
    assert isinstance(e.value, BaseInputError)


def test_size_and_line_limits_are_checked_before_parsing(tmp_path, monkeypatch):
    import lmm.data.inputs as inputs

    p = tmp_path / "long.csv"
    p.write_text(HEADER + "0,0,0,0,0,0,0,0\n" * 20)
    monkeypatch.setattr(inputs, "MAX_INPUT_LOG_LINES", 10)
    with pytest.raises(InputError, match="MAX_INPUT_LOG_LINES") as e:
        load_input_csv(p)
    assert str(p) in str(e.value)
    monkeypatch.setattr(inputs, "MAX_INPUT_LOG_BYTES", 100)
    with pytest.raises(InputError, match="MAX_INPUT_LOG_BYTES"):
        load_input_csv(p)
    with pytest.raises(InputError, match="is a folder"):
        load_input_csv(tmp_path)


@pytest.mark.parametrize("seconds", [float("inf"), float("nan"), 1e308, -1.0])
def test_builtin_length_is_bounded(seconds):
    with pytest.raises(InputError, match="outside"):
        builtin("circle", seconds)
    with pytest.raises(InputError, match="outside"):
        builtin("random:1", seconds)
