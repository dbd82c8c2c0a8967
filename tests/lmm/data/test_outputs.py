"""lmm.data.outputs and lmm.data.reading (issue 36): no output destroys an input, another output or a
special file; two processes never write one path; only regular files are read, numbers are ASCII."""
from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from lmm.data.atomic import write_text_atomic
from lmm.data.outputs import OutputError, check_outputs, release_locks
from lmm.data.reading import NotRegularFileError, ascii_float, ascii_int, open_regular, read_limited

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(autouse=True)
def _release():
    yield
    release_locks()


def test_an_output_that_is_an_input_is_refused_by_path_link_and_hard_link(tmp_path):
    src = tmp_path / "take.input.csv"
    src.write_text("x\n")
    (tmp_path / "link.csv").symlink_to(src)
    os.link(src, tmp_path / "hard.csv")
    for out in (src, tmp_path / "link.csv", tmp_path / "hard.csv", tmp_path / "sub" / ".." / "take.input.csv"):
        (tmp_path / "sub").mkdir(exist_ok=True)
        with pytest.raises(OutputError, match=r"--record: would overwrite the input --input"):
            check_outputs([("--record", out)], [("--input", src)])
    assert src.read_text() == "x\n"


def test_two_outputs_on_one_file_are_refused(tmp_path):
    with pytest.raises(OutputError, match=r"--metrics-json: the same file as the output --record"):
        check_outputs([("--record", tmp_path / "x.bvh"), ("--metrics-json", tmp_path / "x.bvh")], [])
    assert not (tmp_path / "x.bvh").exists()


def test_special_files_are_refused_as_outputs(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    (tmp_path / "null").symlink_to(os.devnull)
    for out, kind in ((fifo, "FIFO"), (tmp_path / "null", "character device"), (tmp_path, "folder")):
        with pytest.raises(OutputError, match=kind):
            check_outputs([("--json", out)], [])
    assert stat.S_ISFIFO(os.stat(fifo).st_mode) and stat.S_ISCHR(os.stat(os.devnull).st_mode)


def test_atomic_write_never_renames_over_a_special_file(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(OSError, match="not a regular file"):
        write_text_atomic(fifo, "data")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert [p.name for p in tmp_path.iterdir()] == ["fifo"]   # no temporary file left


def test_a_second_writer_of_one_path_is_refused_naming_the_holder(tmp_path):
    out = tmp_path / "same.bvh"
    holder = subprocess.Popen([sys.executable, "-c", (
        "import sys, time; from lmm.data.outputs import check_outputs; "
        f"check_outputs([('--record', {str(out)!r})], []); print('locked', flush=True); time.sleep(30)")],
        cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(OutputError, match=rf"being written by another lmm-studio \(process {holder.pid}\)"):
            check_outputs([("--record", out)], [])
    finally:
        holder.kill()
        holder.wait()
    check_outputs([("--record", out)], [])   # the holder is gone: the lock is free again


def test_only_regular_files_are_read(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for path, kind in ((fifo, "FIFO"), ("/dev/zero", "character device"), (tmp_path, "folder")):
        with pytest.raises(NotRegularFileError, match=kind):
            open_regular(path, "input log")
    big = tmp_path / "big"
    big.write_bytes(b"x" * 101)
    with pytest.raises(ValueError, match="larger than 100 bytes"):
        read_limited(big, 100)
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    with pytest.raises(OSError):
        open_regular(loop)


def test_numbers_are_ascii():
    assert ascii_float("-1.5e3") == -1500.0 and ascii_int("42") == 42
    for text in ("9_7.0", "\u0663", "\u0661\u0662"):
        with pytest.raises(ValueError):
            ascii_float(text)
        with pytest.raises(ValueError):
            ascii_int(text)
