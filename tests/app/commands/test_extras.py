"""Offline commands without their optional dependencies: one ``error:`` line, exit 2, before any slow work.

Each command runs in a subprocess where the package is blocked (``sys.modules[name] = None`` makes every
``import name`` fail as if it were not installed) and with an empty database cache, which must stay empty:
the check comes before the database is loaded or built.
"""
import os
import subprocess
import sys
from pathlib import Path

import pytest

from app.commands.extras import require

ROOT = Path(__file__).resolve().parents[3]

RUN_WITHOUT = ("import sys\n"
               "for name in sys.argv[1].split(','):\n"
               "    sys.modules[name] = None\n"
               "from app.cli import main\n"
               "sys.exit(main(sys.argv[2:]))\n")


def run_without(blocked, *args, tmp_path, pythonpath=()):
    cache = tmp_path / "cache"
    cache.mkdir()
    env = dict(os.environ, LMM_STUDIO_CACHE=str(cache),
               PYTHONPATH=os.pathsep.join([*map(str, pythonpath), str(ROOT)]))
    r = subprocess.run([sys.executable, "-c", RUN_WITHOUT, ",".join(blocked), *args], cwd=ROOT,
                       capture_output=True, text=True, timeout=120, env=env)
    return r, cache


def assert_one_line_error(r, *words):
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr, r.stderr
    assert r.stderr.startswith("lmm-studio ") and ": error: " in r.stderr and r.stderr.count("\n") == 1, r.stderr
    for w in words:
        assert w in r.stderr, (w, r.stderr)
    assert r.stdout == ""


@pytest.mark.parametrize("blocked,args,words", [
    (["torch"], ["train", "--iterations", "1"],
     ["lmm-studio train: error: needs torch", "not installed", "scripts/setup train",
      "--index-url https://download.pytorch.org/whl/cpu"]),
    (["torch"], ["train", "projector", "--out", "{tmp}/weights"], ["needs torch", "scripts/setup train"]),
    (["matplotlib"], ["eval", "--json", "{tmp}/eval/metrics.json"],
     ["lmm-studio eval: error: needs matplotlib", "plots", "scripts/setup train", "pip install 'matplotlib"]),
    (["matplotlib"], ["eval", "--plots", "{tmp}/plots"], ["needs matplotlib", "scripts/setup train"]),
    (["onnx"], ["export-onnx", "--out", "{tmp}/onnx"],
     ["lmm-studio export-onnx: error: needs onnx", "scripts/setup train", "pip install 'onnx"]),
])
def test_missing_extra_is_one_line_and_exit_2_before_the_database(tmp_path, blocked, args, words):
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    r, cache = run_without(blocked, *args, tmp_path=tmp_path)
    assert_one_line_error(r, *words)
    assert list(cache.iterdir()) == [], "the database was loaded or built before the check"
    # nothing written: no weights, metrics, plots or ONNX folders
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache"]


def test_a_broken_install_is_reported_with_its_reason(tmp_path):
    # a torch that is there but fails inside (a missing shared library, say) is not "not installed"
    fake = tmp_path / "site" / "torch"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError('libtorch_cpu.so: cannot open shared object file')\n")
    r, cache = run_without([], "train", tmp_path=tmp_path, pythonpath=[fake.parent])
    assert_one_line_error(r, "needs torch", "failed to import", "libtorch_cpu.so", "scripts/setup train")
    assert list(cache.iterdir()) == []


def test_require_is_silent_when_everything_imports(capsys):
    assert require("eval", "json", "csv")
    assert capsys.readouterr().err == ""


def test_require_names_the_first_missing_package(capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "onnx", None)
    assert not require("export-onnx", "json", "onnx")
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "needs onnx" in err and "pip install 'onnx>=1.16'" in err
