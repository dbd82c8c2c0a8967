"""Tests for lmm.data.bvh: the broken-file corpus, mutation fuzzing, agreement with pybvh,
round trips, streaming helpers."""
from __future__ import annotations

import gzip
import math
import pickle
import re
import time
import tracemalloc
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lmm import kinematics, quat
from lmm.data import bvh

HERE = Path(__file__).resolve().parents[2]
CORPUS = HERE / "bvh_corpus"
SHIPPED = sorted((HERE.parent / "lmm" / "data" / "lafan1").glob("*.bvh.gz"))
ORIGINALS = Path("/work/shared/data/lafan1")

# --------------------------------------------------------------------------------------
# small valid files
# --------------------------------------------------------------------------------------

SMALL = """HIERARCHY
ROOT Hips
{
\tOFFSET 0.0 90.0 0.0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
\tJOINT Spine
\t{
\t\tOFFSET 0.0 10.0 0.0
\t\tCHANNELS 3 Zrotation Yrotation Xrotation
\t\tJOINT Head
\t\t{
\t\t\tOFFSET 0.0 15.0 0.0
\t\t\tCHANNELS 3 Zrotation Yrotation Xrotation
\t\t\tEnd Site
\t\t\t{
\t\t\t\tOFFSET 0.0 8.0 0.0
\t\t\t}
\t\t}
\t}
}
MOTION
Frames: 3
Frame Time: 0.033333
1.0 90.0 2.0 0.0 0.0 0.0 5.0 0.0 0.0 0.0 -3.0 0.0
1.5 90.2 2.5 1.0 0.5 0.0 5.5 0.5 0.0 0.0 -3.5 0.5
2.0 90.4 3.0 2.0 1.0 0.0 6.0 1.0 0.0 0.0 -4.0 1.0
"""

# two roots, rotation-first root channels, odd rotation orders, 6 channels on a
# non-root joint, a joint with 0 channels, a joint with only some channels,
# spaces for indentation, a brace on the JOINT line, blank lines in the header.
ODD = """HIERARCHY
ROOT Pelvis
{
  OFFSET 1.0 2.0 3.0
  CHANNELS 6 Yrotation Xposition Xrotation Yposition Zrotation Zposition
  JOINT Arm {
    OFFSET 10.0 0.0 0.0
    CHANNELS 3 Xrotation Zrotation Yrotation

    JOINT Slider
    {
      OFFSET 5.0 1.0 0.0
      CHANNELS 6 Zposition Xrotation Xposition Yrotation Yposition Zrotation
      End Site
      {
        OFFSET 1.0 0.0 0.0
      }
    }
  }
  JOINT Fixed
  {
    OFFSET 0.0 -4.0 0.0
    CHANNELS 0
    JOINT Hinge
    {
      OFFSET 0.0 -3.0 1.0
      CHANNELS 1 Yrotation
      End Site
      {
        OFFSET 0.0 -1.0 0.0
      }
    }
  }
}
ROOT Prop
{
  OFFSET 50.0 0.0 0.0
  CHANNELS 4 Xposition Zposition Zrotation Xrotation
}
MOTION
Frames: 2
Frame Time: 0.0166667
10 1 20 2 30 3  40 50 60  1 2 3 4 5 6  70  7 8 9 10
-10 -1 -20 -2 -30 -3  -40 -50 -60  6 5 4 3 2 1  -70  -7 -8 -9 -10
"""


def corpus_table() -> list[tuple[str, int | None, str]]:
    rows = []
    in_table = False
    for line in (CORPUS / "README.md").read_text().splitlines():
        if line.startswith("|---"):
            in_table = True
            continue
        if in_table and line.startswith("|"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            rows.append((cells[0], None if cells[1] == "-" else int(cells[1]), cells[2]))
    return rows


def check_consistent(a: bvh.Animation) -> None:
    J = a.n_joints
    C = sum(len(c) for c in a.channels)
    assert a.motion.shape == (a.n_frames, C)
    assert a.motion.dtype == np.float64
    assert np.isfinite(a.motion).all()
    assert a.parents.dtype == np.int64 and a.parents.shape == (J,)
    assert all(-1 <= p < j for j, p in enumerate(a.parents))
    assert a.offsets.shape == (J, 3) and np.isfinite(a.offsets).all()
    assert len(a.names) == J and len(set(a.names)) == J
    assert a.frame_time > 0 and math.isfinite(a.frame_time)
    for k, v in a.end_sites.items():
        assert 0 <= k < J and v.shape == (3,) and np.isfinite(v).all()
    cols = [c for j in range(J) for c in a.channel_columns(j)]
    assert cols == list(range(C))


# --------------------------------------------------------------------------------------
# the broken corpus
# --------------------------------------------------------------------------------------

def test_corpus_is_complete():
    listed = {row[0] for row in corpus_table()}
    present = {p.name for p in CORPUS.iterdir() if p.name != "README.md"}
    assert listed == present
    assert len(listed) >= 18


@pytest.mark.parametrize("name,line,keyword", corpus_table())
def test_corpus_file_raises_bvherror(name, line, keyword):
    path = CORPUS / name
    with pytest.raises(bvh.BVHError) as info:
        bvh.load(path)
    e = info.value
    msg = str(e)
    assert e.path == str(path)
    assert name in msg
    assert e.line == line
    if line is not None:
        assert f":{line}:" in msg
    assert keyword.lower() in e.message.lower()
    assert msg == (f"{path}:{line}: {e.message}" if line is not None else f"{path}: {e.message}")


@pytest.mark.parametrize("name,line,keyword", corpus_table())
def test_corpus_through_loads_bytes(name, line, keyword):
    with pytest.raises(bvh.BVHError) as info:
        bvh.loads((CORPUS / name).read_bytes(), path=name)
    assert info.value.line == line


def test_billion_frames_fails_fast_without_allocating():
    text = (CORPUS / "frames_billion.bvh").read_text()
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(bvh.BVHError, match="1000000000"):
            bvh.loads(text, path="big.bvh")
        elapsed = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert elapsed < 1.0
    assert peak < 20 * 2**20


def test_error_str_and_pickle():
    e = bvh.BVHError("expected X", "a.bvh", 3)
    assert str(e) == "a.bvh:3: expected X"
    assert (e.path, e.line, e.message) == ("a.bvh", 3, "expected X")
    assert str(bvh.BVHError("m", None, 3)) == "3: m"
    assert str(bvh.BVHError("m", "p", None)) == "p: m"
    assert str(bvh.BVHError("m")) == "m"
    e2 = pickle.loads(pickle.dumps(e))
    assert (e2.path, e2.line, e2.message, str(e2)) == (e.path, e.line, e.message, str(e))
    assert isinstance(e, Exception)


def test_missing_file_is_an_oserror(tmp_path):
    with pytest.raises(FileNotFoundError):
        bvh.load(tmp_path / "nope.bvh")


# --------------------------------------------------------------------------------------
# limits: accepted ranges and bounded cost, checked before the work
# --------------------------------------------------------------------------------------

def _with_frame_time(text: str, value: str) -> str:
    return re.sub(r"Frame Time: \S+", f"Frame Time: {value}", text)


@pytest.mark.parametrize("value, ok", [("0.0001", True), ("1", True), ("1.0001", False), ("1000", False),
                                       ("0.0000999", False), ("1e-300", False)])
def test_frame_time_range(value, ok):
    text = _with_frame_time(SMALL, value)
    if ok:
        assert bvh.loads(text).frame_time == float(value)
    else:
        with pytest.raises(bvh.BVHError, match="frame time from 0.0001 to 1 seconds") as info:
            bvh.loads(text, path="t.bvh")
        assert info.value.line == SMALL.splitlines().index("Frame Time: 0.033333") + 1


@pytest.mark.parametrize("value, ok", [("1e6", True), ("-1e6", True), ("1.000001e6", False), ("-1e308", False),
                                       ("3e38", False)])
def test_value_magnitude_limit_on_both_parsing_paths(value, ok):
    lines = SMALL.splitlines()
    row = next(i for i, line in enumerate(lines) if line.startswith("1.5 "))
    fast = lines.copy()
    fast[row] = fast[row].replace("1.5 ", value + " ", 1)
    slow = fast.copy()
    slow.append("")  # a blank line is fine for both paths; an extra column below forces the slow one
    offset = [line.replace("OFFSET 0.0 10.0 0.0", f"OFFSET 0.0 {value} 0.0") for line in lines]
    for variant, line in ((fast, row + 1), (offset, next(i for i, s in enumerate(lines) if "10.0" in s) + 1)):
        text = "\n".join(variant) + "\n"
        if ok:
            bvh.loads(text)
        else:
            with pytest.raises(bvh.BVHError, match="value from -1e\\+06 to 1e\\+06") as info:
                bvh.loads(text, path="t.bvh")
            assert info.value.line == line
    if not ok:  # the slow path (a wrong line first would stop it there): the bad value is found too
        with pytest.raises(bvh.BVHError, match="value from"):
            bvh.loads("\n".join(slow) + "\n")


def test_not_a_bvh_file_is_not_echoed():
    secret = "root:x:0:0:root:/root:/bin/bash"
    with pytest.raises(bvh.BVHError) as info:
        bvh.loads(secret + "\n", path="/etc/passwd")
    assert "root" not in info.value.message and str(info.value).startswith("/etc/passwd:1: ")


def test_too_many_joints(monkeypatch):
    monkeypatch.setattr(bvh, "MAX_JOINTS", 2)
    with pytest.raises(bvh.BVHError, match="more than 2 joints") as info:
        bvh.loads(SMALL, path="t.bvh")
    assert info.value.line == SMALL.splitlines().index("\t\tJOINT Head") + 1


def test_declared_frames_and_values_limits(monkeypatch):
    monkeypatch.setattr(bvh, "MAX_VALUES", 35)  # SMALL: 3 frames x 12 channels = 36 values
    with pytest.raises(bvh.BVHError, match="declares more frame lines than the reader accepts"):
        bvh.loads(SMALL)
    monkeypatch.setattr(bvh, "MAX_VALUES", 36)
    bvh.loads(SMALL)
    monkeypatch.setattr(bvh, "MAX_JOINT_FRAMES", 8)  # 3 frames x 3 joints = 9
    with pytest.raises(bvh.BVHError, match="at most .* and 8 frames x joints"):
        bvh.loads(SMALL)
    monkeypatch.setattr(bvh, "MAX_JOINT_FRAMES", 9)
    bvh.loads(SMALL)
    monkeypatch.setattr(bvh, "MAX_FRAMES", 2)
    with pytest.raises(bvh.BVHError, match="at most 2 frames"):
        bvh.loads(SMALL)


def test_joints_without_channels_still_count_against_the_joint_frames_limit():
    """Frames of a channel-free skeleton take no text, but posing them costs memory per joint."""
    joints = "".join(f"JOINT J{i}\n{{\nOFFSET 0 1 0\nCHANNELS 0\n" for i in range(999))
    text = ("HIERARCHY\nROOT R\n{\nOFFSET 0 0 0\nCHANNELS 0\n" + joints + "}\n" * 1000
            + "MOTION\nFrames: 5000000\nFrame Time: 0.01\n")
    tracemalloc.start()
    try:
        with pytest.raises(bvh.BVHError, match="frames x joints"):
            bvh.loads(text)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20 * 2**20


def test_padding_past_what_the_frames_can_hold_is_refused_before_parsing():
    room = 3 * (12 * bvh.MAX_VALUE_CHARS + 2) + 65536
    bvh.loads(SMALL + " " * (room // 2))  # blank space within the slack is fine
    with pytest.raises(bvh.BVHError, match="motion block has"):
        bvh.loads(SMALL + " " * room + "\n")
    one_long_line = SMALL.replace("\n1.5 ", "\n1.5" + " " * 600 + " ")  # a frame line longer than 12 values
    with pytest.raises(bvh.BVHError, match="line of 6.. characters") as info:
        bvh.loads(one_long_line + "x\n")  # the x makes the fast path fail
    assert info.value.line == SMALL.splitlines().index(next(s for s in SMALL.splitlines() if s.startswith("1.5"))) + 1


def _bomb(inflated_mib: int) -> bytes:
    z = zlib.compressobj(9, zlib.DEFLATED, 31)
    spaces = b" " * 2**20
    return z.compress(SMALL.encode()) + b"".join(z.compress(spaces) for _ in range(inflated_mib)) + z.flush()


def test_gzip_bomb_is_abandoned_at_the_text_limit_with_bounded_memory(monkeypatch, tmp_path):
    monkeypatch.setattr(bvh, "MAX_TEXT_BYTES", 2**20)
    bomb = _bomb(64)
    assert len(bomb) < 100_000
    path = tmp_path / "bomb.bvh.gz"
    path.write_bytes(bomb)
    tracemalloc.start()
    try:
        for load in (lambda: bvh.load(path), lambda: bvh.loads(bomb, path=str(path))):
            with pytest.raises(bvh.BVHError, match="inflates to more than 1048576 bytes") as info:
                load()
            assert info.value.path == str(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8 * 2**20  # never the 64 MiB it inflates to


def test_big_plain_file_is_refused_before_reading(monkeypatch, tmp_path):
    path = tmp_path / "big.bvh"
    path.write_text(SMALL)
    monkeypatch.setattr(bvh, "MAX_TEXT_BYTES", len(SMALL) - 1)
    with pytest.raises(bvh.BVHError, match="more than"):
        bvh.load(path)
    with pytest.raises(bvh.BVHError, match="more than"):
        bvh.loads(SMALL)
    monkeypatch.setattr(bvh, "MAX_TEXT_BYTES", len(SMALL))
    bvh.load(path)


def test_truncated_gzip_within_the_limit_still_names_its_line(monkeypatch):
    monkeypatch.setattr(bvh, "MAX_TEXT_BYTES", 2**20)
    small = gzip.compress(SMALL.encode())
    with pytest.raises(bvh.BVHError, match="truncated gzip") as info:
        bvh.loads(small[:-9], path="cut.bvh.gz")  # crc and size cut off: the stream is incomplete
    assert info.value.line == SMALL.count("\n") + 1
    with pytest.raises(bvh.BVHError, match="inflates to more"):  # past the limit, the limit is what is said
        bvh.loads(_bomb(4)[:-9], path="cut.bvh.gz")


def test_slow_path_keeps_values_packed():
    """A bad value on the last line of a long file: the line-by-line pass must not hold Python floats."""
    head, _, rest = SMALL.partition("MOTION\n")
    frames = [line for line in rest.splitlines()[2:] if line.strip()]
    n = 20000
    body = "\n".join(frames * (n // 3)) + "\n" + "1 " * 11 + "2e6\n"
    text = head + f"MOTION\nFrames: {len(frames) * (n // 3) + 1}\nFrame Time: 0.1\n" + body
    tracemalloc.start()
    try:
        with pytest.raises(bvh.BVHError, match="value from"):
            bvh.loads(text)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # text (~0.9 MB) as str and bytes, the fast array (2 MB) and the packed values (2 MB); a list of
    # Python floats would be about 8 MB more
    assert peak < 4 * len(text) + 5 * 2**20


def test_blank_trailing_lines_and_blank_lines_between_frames_are_fine():
    a = bvh.loads(SMALL + "\n\n  \n\t\n")
    b = bvh.loads(SMALL.replace("0.5 0.0\n2.0", "0.5 0.0\n\n2.0"))
    np.testing.assert_array_equal(a.motion, bvh.loads(SMALL).motion)
    np.testing.assert_array_equal(b.motion, a.motion)


def test_zero_frames_is_valid():
    text = SMALL.split("MOTION")[0] + "MOTION\nFrames: 0\nFrame Time: 0.05\n"
    a = bvh.loads(text)
    assert a.motion.shape == (0, 12)
    assert a.global_positions().shape == (0, 3, 3)


# --------------------------------------------------------------------------------------
# property-based mutation of valid files
# --------------------------------------------------------------------------------------

TOKENS = ["{", "}", "JOINT X", "ROOT R", "End Site", "OFFSET 1 2 3", "OFFSET", "CHANNELS 3 Xrotation",
          "CHANNELS 0", "CHANNELS 9", "MOTION", "Frames: 2", "Frames: 99999999999", "Frame Time: 0.1",
          "nan", "inf", "-inf", "1e999", "-", "+", ".", "1.2.3", "0x10", "\x00", "\xe9", "\u2028", "\r",
          "\t", "  ", "Xposition", "Wrotation", "HIERARCHY", "#", "1_000", "\ufeff", "12", "-7", "0"]
NUMBER = re.compile(r"-?\d+(?:\.\d+)?")


def _index(draw, n: int) -> int:
    """An index in range(n), counted from the start or from the end (hypothesis favours small numbers)."""
    i = draw(st.integers(0, n - 1))
    return n - 1 - i if draw(st.booleans()) else i


@st.composite
def mutated(draw):
    seed = draw(st.sampled_from([SMALL, ODD, SMALL.replace("\n", "\r\n")]))
    data = seed.encode()
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["delete", "duplicate", "swap", "flip", "truncate", "insert",
                                   "number", "count"]))
        lines = data.split(b"\n")
        if op in ("delete", "duplicate", "swap") and len(lines) > 1:
            i = _index(draw, len(lines))
            if op == "delete":
                del lines[i]
            elif op == "duplicate":
                lines.insert(i, lines[i])
            else:
                k = _index(draw, len(lines))
                lines[i], lines[k] = lines[k], lines[i]
            data = b"\n".join(lines)
        elif op == "flip" and data:
            i = _index(draw, len(data))
            data = data[:i] + bytes([data[i] ^ draw(st.integers(1, 255))]) + data[i + 1:]
        elif op == "truncate":
            data = data[:_index(draw, len(data) + 1)]
        elif op == "insert":
            i = _index(draw, len(data) + 1)
            tok = draw(st.sampled_from(TOKENS)).encode()
            sep = draw(st.sampled_from([b" ", b"\n", b""]))
            data = data[:i] + sep + tok + sep + data[i:]
        elif op == "number":
            text = data.decode("utf-8", "replace")
            spans = [m.span() for m in NUMBER.finditer(text)]
            if spans:
                s, e = spans[_index(draw, len(spans))]
                new = draw(st.sampled_from(["nan", "inf", "-inf", "abc", "1e999", "", "1e308", "--1",
                                            "1 2", "0", "-0", "3.5", "1e-320"]))
                data = (text[:s] + new + text[e:]).encode()
        elif op == "count":
            text = data.decode("utf-8", "replace")
            spans = [m.span(1) for m in re.finditer(r"(?:CHANNELS|Frames:)\s+(\S+)", text)]
            if spans:
                s, e = spans[_index(draw, len(spans))]
                new = str(draw(st.sampled_from([-2, -1, 0, 1, 2, 3, 4, 5, 6, 7, 10**9, 10**30])))
                data = (text[:s] + new + text[e:]).encode()
    return data


@settings(max_examples=500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated())
def test_mutations_raise_bvherror_or_parse_consistently(data):
    n_lines = data.count(b"\n") + 1
    try:
        a = bvh.loads(data, path="mutant.bvh")
    except bvh.BVHError as e:
        assert e.path == "mutant.bvh"
        assert e.line is None or 1 <= e.line <= n_lines
        assert str(e).startswith("mutant.bvh:")
        return
    check_consistent(a)
    if a.n_frames <= 1000:
        with np.errstate(all="ignore"):
            assert a.global_positions().shape == (a.n_frames, a.n_joints, 3)


# --------------------------------------------------------------------------------------
# semantics on small files
# --------------------------------------------------------------------------------------

def test_small_file_fields():
    a = bvh.loads(SMALL, path="small.bvh")
    check_consistent(a)
    assert a.names == ["Hips", "Spine", "Head"]
    assert a.parents.tolist() == [-1, 0, 1]
    assert a.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
    assert a.channel_columns(1) == [6, 7, 8] and a.channel_columns(-1) == [9, 10, 11]
    assert list(a.end_sites) == [2]
    np.testing.assert_array_equal(a.end_sites[2], [0, 8, 0])
    assert (a.n_frames, a.n_joints, a.frame_time, a.path) == (3, 3, 0.033333, "small.bvh")
    assert a.fps == pytest.approx(30.0, rel=1e-4)
    lp = a.local_positions()
    np.testing.assert_array_equal(lp[:, 0], a.motion[:, :3])
    np.testing.assert_array_equal(lp[:, 1], np.broadcast_to([0, 10, 0], (3, 3)))


def test_odd_file_semantics():
    a = bvh.loads(ODD)
    check_consistent(a)
    assert a.names == ["Pelvis", "Arm", "Slider", "Fixed", "Hinge", "Prop"]
    assert a.parents.tolist() == [-1, 0, 1, 0, 3, -1]
    assert [len(c) for c in a.channels] == [6, 3, 6, 0, 1, 4]
    assert sorted(a.end_sites) == [2, 4]
    f = 0
    lp, lr = a.local_positions(), a.local_rotations()
    # rotation-first root: Yrotation Xposition Xrotation Yposition Zrotation Zposition
    np.testing.assert_array_equal(lp[f, 0], [1, 2, 3])
    np.testing.assert_allclose(lr[f, 0], quat.from_euler(np.radians([10, 20, 30]), "yxz"), atol=1e-15)
    # position channels on a non-root joint replace its offset
    np.testing.assert_array_equal(lp[f, 2], [3, 5, 1])  # Zposition=1, Xposition=3, Yposition=5
    np.testing.assert_allclose(lr[f, 2], quat.from_euler(np.radians([2, 4, 6]), "xyz"), atol=1e-15)
    np.testing.assert_allclose(lr[f, 1], quat.from_euler(np.radians([40, 50, 60]), "xzy"), atol=1e-15)
    # 0 channels: offset and identity
    np.testing.assert_array_equal(lp[:, 3], [[0, -4, 0]] * 2)
    np.testing.assert_array_equal(lr[:, 3], [[1, 0, 0, 0]] * 2)
    # a single rotation channel
    np.testing.assert_allclose(lr[1, 4], quat.from_axis_angle(np.array([0, 1, 0]), np.radians(-70)), atol=1e-15)
    # a root with only some position channels: the offset fills the others
    np.testing.assert_array_equal(lp[f, 5], [7, 0, 8])
    np.testing.assert_allclose(lr[f, 5], quat.from_euler(np.radians([9, 10, 0]), "zxy"), atol=1e-15)
    # second root is independent of the first
    gp = a.global_positions()
    np.testing.assert_array_equal(gp[:, 5], lp[:, 5])


def test_names_with_spaces_and_keyword_layout_variants():
    text = SMALL.replace("JOINT Spine\n\t{", "JOINT Lower Spine {").replace("End Site\n\t\t\t{", "End Site {")
    a = bvh.loads(text)
    assert a.names == ["Hips", "Lower Spine", "Head"]
    np.testing.assert_array_equal(a.motion, bvh.loads(SMALL).motion)
    b = bvh.loads(bvh.dumps(a))
    assert b.names == a.names


def test_crlf_lf_cr_tabs_spaces_and_bom_agree(tmp_path):
    ref = bvh.loads(SMALL)
    variants = [SMALL.replace("\n", "\r\n"), SMALL.replace("\n", "\r"), SMALL.replace("\t", "    "),
                "\ufeff" + SMALL, SMALL.replace(" ", "\t ")]
    for text in variants:
        a = bvh.loads(text)
        assert a.names == ref.names and a.channels == ref.channels
        np.testing.assert_array_equal(a.motion, ref.motion)
        np.testing.assert_array_equal(a.offsets, ref.offsets)


def test_gz_and_crlf_give_identical_results(tmp_path):
    text = ODD.replace("\n", "\r\n")
    (tmp_path / "a.bvh").write_bytes(text.encode())
    (tmp_path / "a.bvh.gz").write_bytes(gzip.compress(ODD.encode()))
    (tmp_path / "gz_without_suffix.bvh").write_bytes(gzip.compress(text.encode()))
    ref = bvh.loads(ODD)
    for name in ["a.bvh", "a.bvh.gz", "gz_without_suffix.bvh"]:
        a = bvh.load(tmp_path / name)
        assert a.path == str(tmp_path / name)
        assert a.names == ref.names and a.channels == ref.channels
        np.testing.assert_array_equal(a.motion, ref.motion)
        np.testing.assert_array_equal(a.global_positions(), ref.global_positions())
    a = bvh.loads(gzip.compress(ODD.encode()))
    np.testing.assert_array_equal(a.motion, ref.motion)


# --------------------------------------------------------------------------------------
# round trips
# --------------------------------------------------------------------------------------

def assert_same_animation(a: bvh.Animation, b: bvh.Animation, atol=1e-4):
    assert a.names == b.names
    assert a.parents.tolist() == b.parents.tolist()
    assert a.channels == b.channels
    assert sorted(a.end_sites) == sorted(b.end_sites)
    assert a.frame_time == pytest.approx(b.frame_time, rel=1e-9)
    np.testing.assert_allclose(a.offsets, b.offsets, atol=atol)
    np.testing.assert_allclose(a.motion, b.motion, atol=atol)
    np.testing.assert_allclose(a.global_positions(), b.global_positions(), atol=atol)


@pytest.mark.parametrize("seed", [SMALL, ODD])
def test_small_round_trip(seed, tmp_path):
    a = bvh.loads(seed)
    text = bvh.dumps(a)
    assert "\r" not in text and text.startswith("HIERARCHY\nROOT ")
    b = bvh.loads(text)
    assert_same_animation(a, b, atol=1e-6)
    for name in ["x.bvh", "x.bvh.gz"]:
        bvh.save(tmp_path / name, a)
        assert_same_animation(a, bvh.load(tmp_path / name), atol=1e-6)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.bvh", "x.bvh.gz"]  # no temp files left
    assert (tmp_path / "x.bvh.gz").read_bytes()[:2] == b"\x1f\x8b"
    assert (tmp_path / "x.bvh").read_text() == text


def test_writer_layout_is_standard():
    text = bvh.dumps(bvh.loads(SMALL))
    lines = text.split("\n")
    assert lines[:6] == ["HIERARCHY", "ROOT Hips", "{", "\tOFFSET 0.000000 90.000000 0.000000",
                         "\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation",
                         "\tJOINT Spine"]
    assert "\t\t\tEnd Site" in lines and "\t\t\t\tOFFSET 0.000000 8.000000 0.000000" in lines
    i = lines.index("MOTION")
    assert lines[i + 1] == "Frames: 3" + " " * (bvh.FRAMES_FIELD_WIDTH - 1)
    assert lines[i + 2] == "Frame Time: 0.033333"
    assert lines[i + 3].split()[:2] == ["1.000000", "90.000000"]
    assert text.endswith("\n") and not text.endswith("\n\n")


def test_precision_argument():
    a = bvh.loads(SMALL)
    a.motion[0, 0] = 1.23456789
    assert "1.23457 " in bvh.dumps(a, precision=5)
    assert "1.2345678900 " in bvh.dumps(a, precision=10)


def random_skeleton_animation(rng, parents, F, orders, position_joints, scale=20.0):
    J = len(parents)
    names = [f"j{j}" for j in range(J)]
    offsets = rng.normal(scale=scale, size=(J, 3))
    rot = quat.normalize(rng.normal(size=(F, J, 4)))
    pos = np.broadcast_to(offsets, (F, J, 3)).copy()
    for j in position_joints:
        pos[:, j] = rng.normal(scale=scale, size=(F, 3))
    end_sites = {j: rng.normal(size=3) for j in range(J) if j not in set(parents)}
    return bvh.Animation.from_local(names, parents, offsets, rot, pos, 1 / 60, rotation_order=orders,
                                    position_joints=position_joints, end_sites=end_sites), rot, pos


@pytest.mark.parametrize("order", ["xyz", "xzy", "yxz", "yzx", "zxy", "zyx"])
def test_from_local_reproduces_rotations_and_positions(order):
    rng = np.random.default_rng(7)
    parents = [-1, 0, 1, 2, 1, 0]
    anim, rot, pos = random_skeleton_animation(rng, parents, 40, order, (0, 3))
    assert anim.channels[0] == ("Xposition", "Yposition", "Zposition") + tuple(f"{c.upper()}rotation" for c in order)
    assert anim.channels[3][:3] == ("Xposition", "Yposition", "Zposition")
    assert len(anim.channels[1]) == 3
    lr = anim.local_rotations()
    np.testing.assert_allclose(np.abs(np.sum(lr * rot, axis=-1)), 1.0, atol=1e-12)
    np.testing.assert_allclose(anim.local_positions(), pos, atol=1e-12)
    g_rot, g_pos = kinematics.forward_kinematics(rot, pos, np.array(parents))
    np.testing.assert_allclose(anim.global_positions(), g_pos, atol=1e-9)
    back = bvh.loads(bvh.dumps(anim))
    np.testing.assert_allclose(back.global_positions(), g_pos, atol=1e-4)


def test_from_local_per_joint_orders_multiple_roots_and_no_channels():
    rng = np.random.default_rng(3)
    parents = [-1, 0, 1, -1, 3, 4]
    orders = ["xzy", "", "yxz", "zyx", "zxy", ""]
    anim, rot, pos = random_skeleton_animation(rng, parents, 25, orders, (0, 2, 3))
    assert anim.channels[1] == () and anim.channels[5] == ()
    assert anim.channels[2] == ("Xposition", "Yposition", "Zposition", "Yrotation", "Xrotation", "Zrotation")
    rot_used = rot.copy()
    rot_used[:, [1, 5]] = [1, 0, 0, 0]
    _, g_pos = kinematics.forward_kinematics(rot_used, pos, np.array(parents))
    np.testing.assert_allclose(anim.global_positions(), g_pos, atol=1e-9)
    back = bvh.loads(bvh.dumps(anim))
    assert_same_animation(anim, back, atol=1e-4)


def test_dumps_reorders_joints_that_are_not_depth_first():
    rng = np.random.default_rng(5)
    parents = [-1, 0, 0, 1, 2, 1]  # depth-first order is 0 1 3 5 2 4
    anim, _, _ = random_skeleton_animation(rng, parents, 10, "zyx", (0, 4))
    with pytest.raises(ValueError, match="depth-first"):
        bvh.header_text(anim)
    back = bvh.loads(bvh.dumps(anim))
    assert back.names == ["j0", "j1", "j3", "j5", "j2", "j4"]
    assert back.parents.tolist() == [-1, 0, 1, 1, 0, 4]
    idx = [back.names.index(n) for n in anim.names]
    np.testing.assert_allclose(back.global_positions()[:, idx], anim.global_positions(), atol=1e-4)
    for k, v in anim.end_sites.items():
        np.testing.assert_allclose(back.end_sites[idx[k]], v, atol=1e-6)


def test_slice():
    a = bvh.loads(SMALL)
    s = a.slice(1, 3)
    assert s.n_frames == 2
    np.testing.assert_array_equal(s.motion, a.motion[1:3])
    s.motion[0, 0] = 99.0
    s.end_sites[2][0] = 99.0
    assert a.motion[1, 0] != 99.0 and a.end_sites[2][0] != 99.0
    assert a.slice(-1, None).n_frames == 1


def test_animation_validates_its_fields():
    a = bvh.loads(SMALL)
    with pytest.raises(ValueError):
        bvh.Animation(a.names, [-1, 0, 3], a.offsets, a.channels, a.motion, a.frame_time)
    with pytest.raises(ValueError):
        bvh.Animation(a.names, a.parents, a.offsets, a.channels, a.motion[:, :5], a.frame_time)
    with pytest.raises(ValueError):
        bvh.Animation(a.names, a.parents, a.offsets, [("Wrotation",), (), ()], np.zeros((1, 1)), 0.1)


# --------------------------------------------------------------------------------------
# streaming helpers
# --------------------------------------------------------------------------------------

def test_streaming_header_and_in_place_frame_count(tmp_path):
    a = bvh.loads(ODD)
    header = bvh.header_text(a, 0)
    assert header.endswith("Frame Time: 0.0166667\n")
    path = tmp_path / "rec.bvh"
    with open(path, "wb") as f:
        f.write(header.encode())
        for i in range(a.n_frames):
            f.write(bvh.format_frames(a.motion[i]).encode())
            f.flush()
            # the file is valid after every frame once the count is rewritten
            with open(path, "r+b") as g:
                g.seek(bvh.frames_field_offset(header))
                g.write(bvh.frames_field(i + 1).encode())
            partial = bvh.load(path)
            np.testing.assert_allclose(partial.motion, a.motion[:i + 1], atol=1e-6)
    assert path.stat().st_size == len(header) + len(bvh.format_frames(a.motion))
    assert bvh.dumps(a) == path.read_text()
    # a header rendered with the final count is byte-identical in length
    assert len(bvh.header_text(a)) == len(header)
    assert bvh.header_text(dict(names=a.names, parents=a.parents, offsets=a.offsets, channels=a.channels,
                                end_sites=a.end_sites, frame_time=a.frame_time), 2) == bvh.header_text(a)


def test_format_frames_shapes_and_checks():
    assert bvh.format_frames(np.zeros((0, 3))) == ""
    assert bvh.format_frames([1.0, -0.0, 2.5], precision=2) == "1.00 0.00 2.50\n"
    assert bvh.format_frames([[1, 2], [3, 4]], precision=0) == "1 2\n3 4\n"
    with pytest.raises(ValueError):
        bvh.format_frames([np.nan])
    with pytest.raises(ValueError):
        bvh.frames_field(10**bvh.FRAMES_FIELD_WIDTH)


# --------------------------------------------------------------------------------------
# LAFAN1 takes: agreement with pybvh, round trips
# --------------------------------------------------------------------------------------

def pybvh_read(path: Path):
    import pybvh
    return pybvh.read_bvh_file(path, world_up="+y")


def decompress_to(src: Path, dst_dir: Path) -> Path:
    dst = dst_dir / src.name[:-3]
    dst.write_bytes(gzip.decompress(src.read_bytes()))
    return dst


@pytest.mark.skipif(not SHIPPED, reason="no shipped LAFAN1 takes")
@pytest.mark.parametrize("take", SHIPPED, ids=[p.name for p in SHIPPED])
def test_agrees_with_pybvh_on_shipped_takes(take, tmp_path):
    ours = bvh.load(take)
    check_consistent(ours)
    assert ours.n_joints == 22 and ours.names[0] == "Hips"
    ref = pybvh_read(decompress_to(take, tmp_path))
    assert ref.joint_names == ours.names
    F = ref.frame_count
    motion = np.column_stack([ref.root_pos, np.rad2deg(ref.joint_angles).reshape(F, -1)])
    assert ours.motion.shape == motion.shape
    np.testing.assert_allclose(ours.motion, motion, rtol=0, atol=1e-9)
    assert ours.frame_time == pytest.approx(ref.frame_time, rel=1e-4)
    np.testing.assert_allclose(ours.global_positions(), ref.joint_positions(), rtol=0, atol=1e-4)


@pytest.mark.skipif(not SHIPPED, reason="no shipped LAFAN1 takes")
def test_lafan_round_trip_through_our_writer_and_pybvh(tmp_path):
    take = SHIPPED[-1]
    a = bvh.load(take)
    path = tmp_path / "rt.bvh"
    bvh.save(path, a)
    b = bvh.load(path)
    assert_same_animation(a, b, atol=1e-4)
    assert np.abs(a.global_positions() - b.global_positions()).max() < 1e-4
    ref = pybvh_read(path)
    np.testing.assert_allclose(ref.joint_positions(), a.global_positions(), rtol=0, atol=1e-4)
    # and pybvh's writer -> our reader
    out = tmp_path / "pybvh_out.bvh"
    ref.write(out)
    c = bvh.load(out)
    np.testing.assert_allclose(c.global_positions(), a.global_positions(), rtol=0, atol=1e-4)


@pytest.mark.parametrize("orders", [["xzy", "yxz", "zxy", "yzx"], ["zyx"] * 4, ["xyz", "xyz", "zyx", "xzy"]])
def test_synthetic_odd_orders_readable_by_pybvh(orders, tmp_path):
    rng = np.random.default_rng(11)
    parents = [-1, 0, 1, 0]
    anim, _, _ = random_skeleton_animation(rng, parents, 30, orders, (0,))
    path = tmp_path / "odd.bvh"
    bvh.save(path, anim)
    ref = pybvh_read(path)
    assert [o.lower() for o in ref.euler_orders] == orders
    np.testing.assert_allclose(ref.joint_positions(), anim.global_positions(), rtol=0, atol=1e-4)


@pytest.mark.skipif(not SHIPPED or not ORIGINALS.is_dir(), reason="needs the uncompressed LAFAN1 originals")
def test_gz_take_equals_its_uncompressed_original():
    take = SHIPPED[0]
    original = ORIGINALS / take.name[:-3]
    if not original.exists():
        pytest.skip(f"{original} missing")
    a, b = bvh.load(take), bvh.load(original)
    assert b"\r\n" in original.read_bytes()[:200]
    assert a.names == b.names
    np.testing.assert_array_equal(a.motion, b.motion)
    np.testing.assert_array_equal(a.offsets, b.offsets)


@pytest.mark.skipif(not SHIPPED, reason="no shipped LAFAN1 takes")
def test_lafan_parse_speed():
    data = gzip.decompress(SHIPPED[0].read_bytes()).decode()
    bvh.loads(data)
    best = min(_timed(lambda: bvh.loads(data)) for _ in range(3))
    assert best < 0.2, f"parsing {len(data) / 1e6:.1f} MB took {best:.3f} s"


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0
