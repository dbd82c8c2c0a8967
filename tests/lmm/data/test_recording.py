"""BVH recording: round trip with our reader and pybvh (joint positions within 0.1 mm), crash safety
(a valid file after every flush or no file; a killed recording keeps all but the last second; a full
disk keeps the last complete flush), determinism."""
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from lmm.data import bvh
from lmm.data.inputs import builtin
from lmm.mm import MotionMatchingController
from lmm.data.recording import BVHRecorder
from lmm.runner import run_headless

ROOT = Path(__file__).resolve().parents[3]


def _record(db, features, path, seconds=4.0, source="zigzag", **kw):
    positions = []
    c = MotionMatchingController(db, features)
    with BVHRecorder(path, db, **kw) as rec:
        run_headless(c, builtin(source, seconds), seconds, recorder=rec,
                     on_step=lambda p, s: positions.append(p.global_positions[1:].astype(np.float64)))
    return np.stack(positions)


def test_round_trip_with_our_reader_and_pybvh(db, features, tmp_path):
    path = tmp_path / "run.bvh"
    expected = _record(db, features, path) * 100.0  # metres -> the file's centimetres
    anim = bvh.load(path)
    assert anim.names == db.names[1:] and anim.n_frames == len(expected)
    assert anim.frame_time == pytest.approx(1 / 60)
    ours = anim.global_positions()
    assert np.abs(ours - expected).max() < 0.01  # cm: 0.1 mm

    import pybvh
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        theirs = pybvh.read_bvh_file(path, world_up="+y")
    assert list(theirs.joint_names) == db.names[1:]
    assert np.abs(theirs.joint_positions() - expected).max() < 0.01


def test_every_flush_leaves_a_valid_file(db, features, tmp_path):
    path = tmp_path / "flush.bvh"
    c = MotionMatchingController(db, features)
    rec = BVHRecorder(path, db, flush_interval_s=1e9)  # flush only when asked
    assert not path.exists()           # the file appears with its first frames, never header-only
    rec.flush()
    assert not path.exists()
    log = builtin("circle", 2.0)
    for i in range(50):
        pose, _ = c.step(log.at(i / 60), 1 / 60)
        rec.write(pose)
        if i % 17 == 16:
            rec.flush()
            assert bvh.load(path).n_frames == i + 1
    assert bvh.load(path).n_frames == 34  # the last 16 frames are still pending
    rec.close()
    assert bvh.load(path).n_frames == 50


def test_same_input_gives_byte_identical_recordings(db, features, tmp_path):
    _record(db, features, tmp_path / "a.bvh", 3.0, "random:5")
    _record(db, features, tmp_path / "b.bvh", 3.0, "random:5")
    assert (tmp_path / "a.bvh").read_bytes() == (tmp_path / "b.bvh").read_bytes()


def test_the_bytes_do_not_depend_on_when_the_recorder_flushed(db, tmp_path):
    """Flushes follow the wall clock, so a long run's frames reach the file in chunks that differ from run
    to run; the page layout of each line depends only on the lines before it, so the files are the same
    bytes whatever the chunks (the first, written whole, included)."""
    rows = _rows(db, 600, seed=3)
    files = []
    for k, every in enumerate((None, 1, 7, 50, 333, [5, 6, 90, 91, 400])):
        path = tmp_path / f"r{k}.bvh"
        rec = BVHRecorder(path, db, flush_interval_s=1e9)
        for i, row in enumerate(rows):
            rec.write_row(row)
            if every is not None and ((i + 1) % every == 0 if isinstance(every, int) else i in every):
                rec.flush()
        rec.close()
        files.append(path.read_bytes())
    assert len(files[0]) > 4 * 4096                  # several pages: lines were moved past boundaries
    assert all(f == files[0] for f in files[1:])


@pytest.mark.slow
def test_killed_recording_keeps_all_but_the_last_second(tmp_path, db):
    out = tmp_path / "killed.bvh"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    cmd = [sys.executable, "-m", "app.cli", "run", "--controller", "mm", "--input", "builtin:random:1",
           "--seconds", "600", "--realtime", "--quiet", "--record", str(out)]
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while not out.exists() or out.stat().st_size == 0:  # the recorder starts right before the first tick
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline
            time.sleep(0.01)
        started = time.monotonic()
        time.sleep(4.0)
        elapsed = time.monotonic() - started
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    anim = bvh.load(out)  # a complete, valid BVH
    assert anim.names == db.names[1:]
    assert anim.n_frames >= int((elapsed - 1.0) * 60), (anim.n_frames, elapsed)
    assert np.isfinite(anim.motion).all()
    csv = out.with_name("killed.input.csv")
    from lmm.data.inputs import load_input_csv
    assert load_input_csv(csv).n_rows >= 1  # the input log is valid too


# ------------------------------------------------------------------------------------------------
# no file without frames, full disks, kills at random moments
# ------------------------------------------------------------------------------------------------

from lmm.data import stream as stream_module  # noqa: E402
from lmm.data.inputs import InputCsvWriter, InputState, load_input_csv  # noqa: E402
from lmm.data.recording import repair  # noqa: E402
from lmm.data.stream import StreamWriteError  # noqa: E402


def _rows(db, n, seed=0):
    rng = np.random.default_rng(seed)
    width = 6 + 3 * (len(db.names) - 2)
    return rng.uniform(-90, 90, size=(n, width))


def _blender_valid(path) -> bool:
    """What Blender's BVH importer (io_anim_bvh/import_bvh.py) needs of the motion: every line after
    'Frame Time:' split into at least as many numbers as the header declares channels (it reads lines
    to the end of the file, whatever 'Frames:' says), a parseable count, and at least one frame."""
    text = Path(path).read_text()
    head, _, body = text.partition("\nFrame Time:")
    n_channels = sum(int(line.split()[1]) for line in head.splitlines() if line.strip().startswith("CHANNELS"))
    count = int(head.rsplit("Frames:", 1)[1].split()[0])
    lines = [ln.split() for ln in body.splitlines()[1:] if ln.split()]
    return count >= 0 and len(lines) >= 1 and all(len(ln) >= n_channels for ln in lines) and all(
        np.isfinite(float(v)) for ln in lines for v in ln)


def test_a_recording_without_frames_leaves_no_file(db, tmp_path):
    bvh_path, csv_path = tmp_path / "none.bvh", tmp_path / "none.input.csv"
    BVHRecorder(bvh_path, db).close()
    InputCsvWriter(csv_path).close()
    assert list(tmp_path.iterdir()) == []   # no file, no temporary file


def test_recorder_refuses_unwritable_targets_at_the_start(db, tmp_path):
    with pytest.raises(FileNotFoundError, match="missing"):
        BVHRecorder(tmp_path / "missing" / "x.bvh", db)
    (tmp_path / "taken.bvh").write_text("someone's file")
    with pytest.raises(FileExistsError, match="taken.bvh"):
        BVHRecorder(tmp_path / "taken.bvh", db, overwrite=False)
    assert (tmp_path / "taken.bvh").read_text() == "someone's file"
    with pytest.raises(IsADirectoryError):
        BVHRecorder(tmp_path, db)
    if os.geteuid() != 0:    # root writes anywhere
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        try:
            with pytest.raises(PermissionError, match="ro"):
                BVHRecorder(ro / "x.bvh", db)
        finally:
            ro.chmod(0o700)


class _Disk:
    """A disk that holds ``capacity`` more bytes: os.write / os.pwrite in lmm.data.stream write what
    fits (a short write) and then fail with ENOSPC, as a full file system does."""

    def __init__(self, monkeypatch, capacity):
        self.left = capacity
        self.real_write, self.real_pwrite = os.write, os.pwrite
        monkeypatch.setattr(stream_module.os, "write", self.write)
        monkeypatch.setattr(stream_module.os, "pwrite", self.pwrite)

    def _room(self, fd, data, offset):
        size = os.fstat(fd).st_size
        end = (os.lseek(fd, 0, os.SEEK_CUR) if offset is None else offset) + len(data)
        grow = max(end - size, 0)              # overwriting bytes in place needs no space
        if grow <= self.left:
            self.left -= grow
            return len(data)
        if self.left == 0:
            raise OSError(28, "No space left on device")
        n = len(data) - (grow - self.left)
        self.left = 0
        return n

    def write(self, fd, data):
        return self.real_write(fd, bytes(data)[:self._room(fd, bytes(data), None)])

    def pwrite(self, fd, data, offset):
        return self.real_pwrite(fd, bytes(data)[:self._room(fd, bytes(data), offset)], offset)


@pytest.mark.parametrize("capacity", [0, 500, 4000, 20_000, 60_000, 100_003])
def test_full_disk_keeps_a_valid_recording_or_none(db, tmp_path, monkeypatch, capacity):
    path = tmp_path / "full.bvh"
    rows = _rows(db, 240)
    rec = BVHRecorder(path, db, flush_interval_s=1e9)
    disk = _Disk(monkeypatch, capacity)
    error = None
    flushed = []
    try:
        for i, row in enumerate(rows):
            rec.write_row(row)
            if i % 10 == 9:
                rec.flush()
                flushed.append(i + 1)
    except StreamWriteError as e:
        error = e
    rec.close()            # after a failure: nothing more, no second error
    rec.close()
    assert error is not None and error.errno == 28 and error.filename == str(path)
    assert "full.bvh" in str(error) and "\n" not in str(error)
    monkeypatch.undo()
    assert [p.name for p in tmp_path.iterdir() if p.name != "full.bvh"] == []   # no temporary file left
    if not path.exists():
        assert rec.frames_written == 0 and "nothing was written" in str(error)
        return
    anim = bvh.load(path)
    assert anim.n_frames == rec.frames_written >= 10 and anim.n_frames in flushed
    assert np.allclose(anim.motion, rows[:anim.n_frames], atol=1e-6)
    assert _blender_valid(path)


def test_full_disk_keeps_a_valid_input_log(tmp_path, monkeypatch):
    path = tmp_path / "in.csv"
    w = InputCsvWriter(path, flush_interval_s=1e9)
    w.write(0.0, InputState(0.1, 0.2, 0, 0, False, False, 0.0))
    w.flush()
    _Disk(monkeypatch, 40)
    with pytest.raises(StreamWriteError):
        for i in range(1, 100):
            w.write(i / 60, InputState(i / 100, 0.2, 0, 0, False, False, 0.0))
            w.flush()
    w.close()
    monkeypatch.undo()
    assert path.read_bytes().endswith(b"\n")        # whole rows only
    assert 1 <= load_input_csv(path).n_rows < 40 // 20  + 2


def _record_until_killed(db, bvh_path, csv_path, ready_w):
    """Child: announce, then record random frames and inputs at 600 fps with 20 ms flushes, forever."""
    rows = _rows(db, 64)
    rec = BVHRecorder(bvh_path, db, flush_interval_s=0.02)
    inp = InputCsvWriter(csv_path, flush_interval_s=0.02)
    os.write(ready_w, b"1")
    i = 0
    while True:
        rec.write_row(rows[i % 64])
        inp.write(i / 60, InputState((i % 7) / 7, 0.0, 0, 0, False, False, 0.0))
        i += 1
        time.sleep(1 / 600)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_kill_at_random_moments_leaves_valid_files_or_none(db, tmp_path):
    rng = np.random.default_rng(12)
    # a third of the kills within the first 0.1 s (before or during the first flush), all within 0.6 s
    delays = np.concatenate([rng.uniform(0, 0.1, 8), rng.uniform(0, 0.6, 16)])
    outcomes = {"absent": 0, "valid": 0, "valid after repair": 0}
    for k, delay in enumerate(delays):
        bvh_path, csv_path = tmp_path / f"k{k}.bvh", tmp_path / f"k{k}.input.csv"
        ready_r, ready_w = os.pipe()
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child
            try:
                os.close(ready_r)
                _record_until_killed(db, bvh_path, csv_path, ready_w)
            finally:
                os._exit(1)
        os.close(ready_w)
        assert os.read(ready_r, 1) == b"1"
        os.close(ready_r)
        time.sleep(float(delay))
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        if bvh_path.exists():
            assert _blender_valid(bvh_path), (k, delay)
            try:
                anim = bvh.load(bvh_path)
                outcomes["valid"] += 1
            except bvh.BVHError:
                # killed between appending frames and rewriting the count (see lmm.data.stream)
                repair(bvh_path)
                anim = bvh.load(bvh_path)
                outcomes["valid after repair"] += 1
            assert anim.n_frames >= 1 and np.isfinite(anim.motion).all()
        else:
            outcomes["absent"] += 1
        if csv_path.exists():
            assert load_input_csv(csv_path).n_rows >= 1
    assert outcomes["absent"] + outcomes["valid"] + outcomes["valid after repair"] == len(delays)
    assert outcomes["valid"] >= 1, outcomes   # the kills did land after the first flushes too


def test_repair_fixes_a_count_lower_than_the_frames(db, tmp_path):
    path = tmp_path / "r.bvh"
    rows = _rows(db, 30)
    with BVHRecorder(path, db) as rec:
        for row in rows:
            rec.write_row(row)
    text = path.read_text()
    # as if killed between the append of 10 more frames and the count rewrite, inside a write
    text = text.replace("Frames: 30        ", "Frames: 20        ") + "1.0 2.0 3"
    path.write_text(text)
    with pytest.raises(bvh.BVHError):
        bvh.load(path)
    assert repair(path) == 30
    assert np.allclose(bvh.load(path).motion, rows, atol=1e-6)


def _can_mount_tmpfs(where) -> bool:
    if os.geteuid() != 0:
        return False
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(where)], capture_output=True)
    return r.returncode == 0


@pytest.mark.slow
def test_run_record_on_a_real_full_disk(tmp_path):
    """`run --record` onto a 256 KiB tmpfs: one error line, exit 1, the recording loads or is absent."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    if not _can_mount_tmpfs(mnt):
        pytest.skip("cannot mount a tmpfs here (needs root)")
    try:
        out = mnt / "take.bvh"
        cmd = [sys.executable, "-m", "app.cli", "run", "--controller", "mm", "--input", "builtin:random:1",
               "--seconds", "30", "--quiet", "--record", str(out)]
        r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert r.returncode == 1, r.stderr
        assert len(lines) == 1 and "Traceback" not in r.stderr and "take" in lines[0], r.stderr
        assert "No space left" in lines[0]
        leftovers = sorted(p.name for p in mnt.iterdir())
        assert all(not n.startswith(".") for n in leftovers), leftovers
        if out.exists():
            anim = bvh.load(out)
            assert anim.n_frames >= 1 and _blender_valid(out)
        csv = mnt / "take.input.csv"
        if csv.exists():
            assert load_input_csv(csv).n_rows >= 1
    finally:
        subprocess.run(["umount", str(mnt)], check=False)


def test_appended_frames_never_cross_a_page_so_a_kill_leaves_whole_lines(db, tmp_path):
    """Linux stops a write at a page boundary when the process is killed. Appended chunks keep each frame
    line inside one page of the file (blanks before a line that would cross), so the file cut at any page
    boundary past its first chunk (what such a kill leaves) still opens in Blender's importer, whole
    frames only, and loads after the count repair; the motion read back is the one written."""
    from lmm.data.stream import PAGE, lines_within_pages

    lines = b"".join(b"%d %s\n" % (i, b"7" * (i * 37 % 300)) for i in range(200))
    laid = lines_within_pages(lines, 1000, page=512)
    assert laid.split() == lines.split() and len(laid) > len(lines)     # blanks added, nothing else
    pos = 1000
    for line in laid.splitlines(keepends=True):
        if line.strip():
            start = pos + len(line) - len(line.lstrip(b" "))           # the line's first non-blank
            assert start // 512 == (pos + len(line) - 1) // 512      # ... and its newline: one page
        pos += len(line)
    path = tmp_path / "p.bvh"
    rows = _rows(db, 400)
    rec = BVHRecorder(path, db, flush_interval_s=1e9)
    first_chunk = None
    for i, row in enumerate(rows):
        rec.write_row(row)
        if i % 50 == 49:
            rec.flush()
            first_chunk = first_chunk or path.stat().st_size     # written whole, then renamed
    rec.close()
    full = path.read_bytes()
    anim = bvh.load(path)
    assert anim.n_frames == 400 and np.allclose(anim.motion, rows, atol=1e-6)
    cut_points = [c for c in range(PAGE, len(full), PAGE) if c > first_chunk]
    assert len(cut_points) >= 10
    for c in cut_points:
        cut = tmp_path / "cut.bvh"
        cut.write_bytes(full[:c])
        assert _blender_valid(cut), c
        repair(cut)
        got = bvh.load(cut)
        assert 50 <= got.n_frames < 400 and np.allclose(got.motion, rows[:got.n_frames], atol=1e-6)
