"""Damaged derived arrays (issue 36): a bit flip, a NaN or a 0-byte ``.derived/*.npy`` gave a different
recording with exit 0, or stopped run, coverage and even ``build-db --rebuild`` with ``EOFError``. Each
is now found by its checksum, computed again with a one-line note, and the recording is the same."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]
MANIFEST = ROOT / "tests" / "corpus" / "good" / "manifest.json"


def cli(cache, *args):
    env = {**os.environ, "LMM_STUDIO_CACHE": str(cache), "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "app.cli", *map(str, args)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=180)


def _flip(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[-5] ^= 0x10          # one bit of the last value
    path.write_bytes(bytes(data))


def _nan(path: Path) -> None:
    a = np.load(path)
    if a.dtype.kind != "f" or a.size == 0:
        _flip(path)
        return
    a = a.copy()
    a.flat[0] = np.nan
    np.save(path, a)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    cache = tmp_path_factory.mktemp("cache")
    out = tmp_path_factory.mktemp("out")
    r = cli(cache, "run", "--manifest", MANIFEST, "--input", "builtin:circle", "--seconds", "2", "--quiet",
            "--record", out / "first.bvh")
    assert r.returncode == 0, r.stderr
    entries = sorted(cache.glob("*.derived/*.npy"))
    assert entries and all(Path(str(e) + ".crc32").is_file() for e in entries)
    return cache, out, entries


@pytest.mark.parametrize("damage", ["empty", "flip", "nan"])
def test_a_damaged_derived_array_is_computed_again_with_a_note(built, damage):
    cache, out, entries = built
    for entry in entries:
        {"empty": lambda p: p.write_bytes(b""), "flip": _flip, "nan": _nan}[damage](entry)
    r = cli(cache, "run", "--manifest", MANIFEST, "--input", "builtin:circle", "--seconds", "2", "--quiet",
            "--record", out / f"{damage}.bvh")
    assert r.returncode == 0, r.stderr
    notes = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert notes and all(ln.startswith("note: ") and "damaged cached array" in ln for ln in notes), r.stderr
    assert (out / f"{damage}.bvh").read_bytes() == (out / "first.bvh").read_bytes()
    r = cli(cache, "run", "--manifest", MANIFEST, "--input", "builtin:circle", "--seconds", "1", "--quiet")
    assert r.returncode == 0 and r.stderr == "", r.stderr    # written again, intact: no note the next time


def test_a_rebuild_does_not_depend_on_a_damaged_entry(built):
    cache, _, entries = built
    for entry in sorted(cache.glob("*.derived/*.npy")):
        entry.write_bytes(b"")
    r = cli(cache, "build-db", "--manifest", MANIFEST, "--rebuild", "--quiet", "--no-checks")
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
