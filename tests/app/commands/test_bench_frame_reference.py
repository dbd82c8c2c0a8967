"""``lmm-studio bench``'s whole frames against the C++ reference (app/commands/bench_frame_reference.py,
app/commands/frame_reference.cpp), and the bench without a C++ compiler."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from app.commands import bench_frame_reference as frames
from app.commands import cpp_reference

ROOT = Path(__file__).resolve().parents[3]
needs_cxx = pytest.mark.skipif(cpp_reference.compiler() is None, reason="no C++ compiler")


def test_a_cxx_that_is_not_there_means_no_compiler(monkeypatch, tmp_path):
    monkeypatch.setenv("CXX", "/nonexistent/c++")
    assert cpp_reference.compiler() is None
    with pytest.raises(RuntimeError, match="no C.. compiler"):
        cpp_reference.build(Path("/nonexistent"), frames.SOURCE)
    monkeypatch.delenv("CXX")
    monkeypatch.setenv("PATH", str(tmp_path))      # nothing on PATH either
    assert cpp_reference.compiler() is None


def test_bench_without_a_compiler_says_so_in_one_line(tmp_path):
    out = tmp_path / "bench.json"
    env = dict(os.environ, CXX="/nonexistent/c++")
    r = subprocess.run([sys.executable, "-m", "app.cli", "bench", "--sections", "frame", "--queries", "20",
                        "--frame-ticks", "60", "--frame-rounds", "1", "--json", str(out)], cwd=ROOT,
                       capture_output=True, text=True, timeout=600, env=env)
    assert r.returncode == 0, r.stderr
    notes = [ln for ln in r.stderr.splitlines() if "C++" in ln]
    assert len(notes) == 1 and "no C++ compiler" in notes[0], r.stderr
    f = json.loads(out.read_text())["frame"]
    assert f["cpp_flags"] == "-O3 -ffast-math -march=native" and f["cpp_compiler"] is None
    assert f["cpp_frame_source"] == f["lmm_network_cpp_source"] == "not measured: no C++ compiler"
    assert f["cpp_mm_frame_us"] is None and f["cpp_lmm_frame_us"] is None and f["lmm_network_stepper_cpp_us"] is None
    assert f["mm_us"] > 0 and f["lmm_us"] > 0          # our own figures are still there


@pytest.fixture(scope="module")
def controllers(db, features):
    from app.commands.bench_runs import learned_factory
    from lmm.mm import MotionMatchingController

    return MotionMatchingController(db, features), learned_factory(db, features)()


@pytest.fixture(scope="module")
def frame_run(controllers, tmp_path_factory):
    """The C++ frames over 4 s of the bench's inputs: (its output, the data file, the program)."""
    if cpp_reference.compiler() is None:
        pytest.skip("no C++ compiler")
    from lmm.data.cache import default_cache_dir

    mm, lmm = controllers
    exe = cpp_reference.build(default_cache_dir(), frames.SOURCE)
    data = tmp_path_factory.mktemp("frames") / "frames.bin"
    frames.write_frame_file(data, mm, lmm.nets, frames.frame_inputs(240))
    r = subprocess.run([str(exe), str(data), "2"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout), data, exe


def test_the_cpp_frames_do_our_work(frame_run, controllers):
    out, _, _ = frame_run
    mm, lmm = controllers
    assert frames.check_output(out, mm, lmm.nets) == ""
    for name in ("mm", "lmm"):
        run = out[name]
        times = run["median_us"] + run["mean_us"] + run["searching_us"]
        assert len(run["median_us"]) == 2 and all(0 < m <= 1e5 for m in times)
        # a search every 0.1 s of the 4 s, as ours (a forced one may add to both)
        assert run["searches"][0] == run["searches"][1] >= 40
    assert len(out["searches"]) == 3 and all(len(s["query"]) == mm.features.n_dims for s in out["searches"])


def test_a_wrong_search_or_decoding_is_refused(frame_run, controllers):
    out, _, _ = frame_run
    mm, lmm = controllers
    bad = json.loads(json.dumps(out))
    s = bad["searches"][0]
    X, q = mm.features.normalized, np.asarray(s["query"], np.float32)
    s["best"] = int(np.argmax(np.einsum("ij,ij->i", X - q, X - q)))   # the worst frame
    assert "the C++ search chose frame" in frames.check_output(bad, mm, lmm.nets)
    bad = json.loads(json.dumps(out))
    bad["start_rotations"][3] = [0.0, 1.0, 0.0, 0.0]
    assert "decoding of the start state differs" in frames.check_output(bad, mm, lmm.nets)


@needs_cxx
@pytest.mark.parametrize("cut", [3, 1000, -9])
def test_a_broken_frame_file_is_one_line_naming_it(frame_run, tmp_path, cut):
    _, data, exe = frame_run
    bad = tmp_path / "bad.bin"
    bad.write_bytes(data.read_bytes()[:cut])
    r = subprocess.run([str(exe), str(bad), "1"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and r.stdout == ""
    assert len(r.stderr.strip().splitlines()) == 1 and str(bad) in r.stderr
