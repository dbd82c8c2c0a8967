"""lmm.data.outputs and lmm.data.reading (issue 36): no output destroys an input, another output or a
special file; two processes never write one path; only regular files are read, numbers are ASCII."""
from __future__ import annotations

import os
import shlex
import shutil
import stat
import subprocess
import sys
from contextlib import contextmanager
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


@contextmanager
def holder(take: str):
    """A process that runs ``take`` (Python taking a lock) and then waits; yields its pid once it holds it."""
    p = subprocess.Popen([sys.executable, "-c", f"import time\n{take}\nprint('held', flush=True)\ntime.sleep(30)"],
                         cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "held"
        yield p.pid
    finally:
        p.kill()
        p.wait()


def test_a_second_writer_of_one_path_is_refused_naming_the_holder(tmp_path):
    out = tmp_path / "same.bvh"
    with holder(f"from lmm.data.outputs import check_outputs; check_outputs([('--record', {str(out)!r})], [])") as pid:
        with pytest.raises(OutputError, match=rf"being written by another lmm-studio \(process {pid}\)"):
            check_outputs([("--record", out)], [])
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


def test_two_runs_recording_one_file_one_refuses_the_other_completes(tmp_path):
    """Two ``run --record same.bvh`` at once (issue 36: both exited 0 and A's recording was B's): the
    second is refused at once naming the first's process; the first's recording holds all its frames."""
    from lmm.data import bvh

    out = tmp_path / "same.bvh"
    env = {**os.environ, "LMM_STUDIO_CACHE": os.environ.get("LMM_STUDIO_CACHE", str(tmp_path / "cache"))}
    cmd = [sys.executable, "-m", "app.cli", "run", "--input", "builtin:circle", "--quiet", "--record", str(out)]
    first = subprocess.Popen(cmd + ["--seconds", "4", "--realtime"], cwd=ROOT, env=env, stderr=subprocess.PIPE,
                             text=True)
    try:
        import time
        deadline = time.monotonic() + 60
        while not out.exists() and time.monotonic() < deadline and first.poll() is None:
            time.sleep(0.05)   # the first run has its lock once its recording appears
        second = subprocess.run(cmd + ["--seconds", "1"], cwd=ROOT, env=env, capture_output=True, text=True,
                                timeout=120)
    finally:
        first.wait(timeout=120)
    assert first.returncode == 0, first.stderr.read()
    assert second.returncode == 1 and second.stderr.count("\n") == 1, second.stderr
    assert f"process {first.pid}" in second.stderr and "same.bvh" in second.stderr, second.stderr
    assert bvh.load(out).n_frames == 240


DEVICE_OUTPUTS = [   # every output option of the file-writing commands, given a device node ({D})
    ["run", "--input", "builtin:circle", "--seconds", "1", "--quiet", "--record", "{D}"],
    ["run", "--input", "builtin:circle", "--seconds", "1", "--quiet", "--record", "{T}/r.bvh", "--record-input", "{D}"],
    ["run", "--input", "builtin:circle", "--seconds", "1", "--quiet", "--metrics-json", "{D}"],
    ["run", "--input", "builtin:circle", "--seconds", "1", "--quiet", "--session", "{D}"],
    ["build-db", "--manifest", "{good}/manifest.json", "--quiet", "--no-checks", "--out", "{D}"],
    ["check-data", "--manifest", "{good}/manifest.json", "--quiet", "--json", "{D}"],
    ["check-data", "--manifest", "{good}/manifest.json", "--quiet", "--png", "{D}"],
    ["coverage", "--manifest", "{good}/manifest.json", "--json", "{D}"],
    ["view", "{good}/walk.bvh", "--screenshot", "{D}"],
    ["compare", "{good}/walk.bvh", "{good}/walk.bvh", "--json", "{D}"],
    ["input-from", "{good}/walk.bvh", "--manifest", "{good}/manifest.json", "--out", "{D}"],
    ["physics", "{good}/walk.bvh", "--json", "{D}"],
]


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="making a device node needs root")
@pytest.mark.parametrize("argv", DEVICE_OUTPUTS, ids=lambda a: f"{a[0]}-{a[-2]}")
def test_a_device_given_as_an_output_stays_a_device(tmp_path, argv, capsys):
    """As root, ``/dev/null`` given as an output was replaced by a regular file (the atomic rename went
    over it). A character device made here (1, 3: what /dev/null is) must be refused and stay a device."""
    from app.cli import main

    dev = tmp_path / "null"
    try:
        os.mknod(dev, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    except (OSError, AttributeError) as e:
        pytest.skip(f"cannot make a device node here ({e})")
    good = ROOT / "tests" / "corpus" / "good"
    rc = main([a.format(D=dev, T=tmp_path, good=good) for a in argv])
    err = capsys.readouterr().err
    assert rc == 1 and "character device" in err and str(dev) in err and err.count("\n") == 1, err
    assert stat.S_ISCHR(os.lstat(dev).st_mode)


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0 or not shutil.which("unshare"),
                    reason="needs root and unshare")
def test_dev_null_as_every_output_stays_a_character_device_in_a_private_mount_namespace(tmp_path):
    """The issue's own check: in a private mount namespace (a private /dev holding a fresh null device),
    ``/dev/null`` given as every output path of every command above is refused and stays a device."""
    good = ROOT / "tests" / "corpus" / "good"
    script = ["mount -t tmpfs tmpfs /dev", "mknod -m 666 /dev/null c 1 3"]
    for argv in DEVICE_OUTPUTS:
        args = " ".join(shlex.quote(a.format(D="/dev/null", T=tmp_path, good=good)) for a in argv)
        script.append(f"{shlex.quote(sys.executable)} -m app.cli {args} 2>>{tmp_path}/err; echo $? >>{tmp_path}/rc")
    script.append(f"stat -c %F /dev/null >{tmp_path}/kind")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run(["unshare", "-m", "sh", "-c", "; ".join(script)], cwd=ROOT, env=env, capture_output=True,
                       text=True, timeout=300)
    if r.returncode != 0 and not (tmp_path / "kind").exists():
        pytest.skip(f"no private mount namespace here: {r.stderr.strip()[:200]}")
    assert (tmp_path / "rc").read_text().split() == ["1"] * len(DEVICE_OUTPUTS), (tmp_path / "err").read_text()
    assert (tmp_path / "err").read_text().count("character device") == len(DEVICE_OUTPUTS)
    assert (tmp_path / "kind").read_text().strip() == "character special file"


def test_a_stream_holds_its_path_until_closed(tmp_path):
    """Every streamed recording (run's, the studio's, input logs) locks its path while open."""
    from lmm.data.stream import StreamFile

    out = tmp_path / "take.bvh"
    with holder(f"from lmm.data.stream import StreamFile; s = StreamFile({str(out)!r}, b'h')") as pid:
        with pytest.raises(OutputError, match=f"process {pid}"):
            StreamFile(out, b"h")
    StreamFile(out, b"h").close()   # the holder is gone: the path is free
