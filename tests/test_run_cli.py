"""``lmm-studio run`` and ``lmm-studio bench`` end to end (subprocesses, as a user runs them)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from lmm.data import bvh

ROOT = Path(__file__).resolve().parents[1]
CORPUS = Path(__file__).parent / "input_corpus"


def cli(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "app.cli", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout, env=dict(os.environ))


BROKEN = {
    "missing_column.csv": ("line 1", "column 7"),
    "nan_value.csv": ("line 3", "column 2"),
    "time_backwards.csv": ("line 5", "column 1"),
    "non_numeric.csv": ("line 3", "column 3"),
    "bad_flag.csv": ("line 3", "column 6"),
    "short_row.csv": ("line 3", "column 6"),
}


@pytest.mark.parametrize("name", sorted(BROKEN))
def test_bad_input_logs_exit_with_line_and_column(name):
    r = cli("run", "--input", str(CORPUS / name), "--seconds", "1")
    assert r.returncode == 1
    assert "Traceback" not in r.stderr
    line, column = BROKEN[name]
    assert r.stderr.startswith("lmm-studio run: error: ") and name in r.stderr and line in r.stderr and column in r.stderr, r.stderr
    assert r.stderr.count("\n") == 1


@pytest.mark.parametrize("spec, words", [("builtin:no-such-scenario", "unknown built-in input 'no-such-scenario'"),
                                         ("builtin:random:x", "seed"),
                                         ("does/not/exist.csv", "no such input file")])
def test_bad_input_specs(spec, words):
    r = cli("run", "--input", spec, "--seconds", "1")
    assert r.returncode == 1 and "Traceback" not in r.stderr and words in r.stderr, r.stderr


def test_bad_tuning_preset(tmp_path):
    p = tmp_path / "preset.json"
    p.write_text(json.dumps({"transition_cost": -3}))
    r = cli("run", "--input", "builtin:circle", "--seconds", "1", "--tuning", str(p))
    assert r.returncode == 1 and "transition_cost" in r.stderr and "Traceback" not in r.stderr


def test_run_records_and_writes_metrics(tmp_path):
    out = tmp_path / "rec" / "run.bvh"
    metrics = tmp_path / "m.json"
    r = cli("run", "--controller", "mm", "--input", "builtin:stop-and-go", "--seconds", "3", "--record", str(out),
            "--metrics-json", str(metrics))
    assert r.returncode == 0, r.stderr
    assert "foot_skating_cm_s" in r.stdout
    report = json.loads(metrics.read_text())
    assert report["frames"] == 180 and report["metrics"]["ticks"] == 180
    assert report["metrics"]["foot_skating_cm_s"] >= 0 and report["recording"]["frames"] == 180
    assert bvh.load(out).n_frames == 180
    # the input log written beside it replays to a byte-identical recording
    csv = out.with_name("run.input.csv")
    out2 = tmp_path / "replay.bvh"
    r = cli("run", "--input", str(csv), "--seconds", "3", "--record", str(out2), "--quiet")
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == out2.read_bytes()


def test_bench_json_sections(tmp_path):
    out = tmp_path / "bench.json"
    r = cli("bench", "--json", str(out), "--queries", "120", timeout=600)
    assert r.returncode == 0, r.stderr
    res = json.loads(out.read_text())
    s = res["search"]
    assert s["frames"] > 50000 and s["queries"] == 120
    assert s["agreement"] == 1.0 and s["topk_agreement"] == 1.0
    assert s["bruteforce_us"] > s["accelerated_us"] > 0
    assert res["frame"]["mm_us"] > 0
    assert "[search]" in r.stdout
    r = cli("bench", "--sections", "nope")
    assert r.returncode == 2 and "unknown bench section" in r.stderr
