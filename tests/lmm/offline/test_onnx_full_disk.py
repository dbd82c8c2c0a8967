"""export-onnx on a full disk keeps the old set whole (issue 36: it left the old decompressor.onnx beside
new files): the three models are written to temporaries first and renamed only when all are on disk."""
from __future__ import annotations

import builtins
import errno
import os

import pytest

pytest.importorskip("onnx")

from lmm.learned import DEFAULT_WEIGHTS  # noqa: E402

NAMES = ("decompressor", "stepper", "projector")


def disk_full_on_the_second_file(monkeypatch):
    """``open`` in lmm.data.atomic whose second file's writes fail with ENOSPC."""
    import lmm.data.atomic as atomic

    opened = []

    class Full:
        def __init__(self, f):
            self._f = f

        def write(self, data):
            raise OSError(errno.ENOSPC, "No space left on device")

        def __getattr__(self, name):
            return getattr(self._f, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return self._f.__exit__(*exc)

    def full_open(path, *a, **k):
        f = builtins.open(path, *a, **k)
        opened.append(path)
        return Full(f) if len(opened) == 2 else f

    monkeypatch.setattr(atomic, "open", full_open, raising=False)
    return opened


@pytest.mark.skipif(not DEFAULT_WEIGHTS.exists(), reason="no shipped weights")
def test_a_full_disk_keeps_the_old_set_and_leaves_no_temporary(tmp_path, monkeypatch, capsys):
    from app.cli import main

    old = {name: f"old {name}".encode() for name in NAMES}
    for name, data in old.items():
        (tmp_path / f"{name}.onnx").write_bytes(data)
    opened = disk_full_on_the_second_file(monkeypatch)
    assert main(["export-onnx", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "stepper.onnx" in err[0] and "No space left" in err[0], err
    assert len(opened) == 2   # the projector was never started
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == {f"{n}.onnx": d for n, d in old.items()}
    monkeypatch.undo()
    assert main(["export-onnx", "--out", str(tmp_path)]) == 0   # with room, the whole set is replaced
    assert sorted(os.listdir(tmp_path)) == sorted(f"{n}.onnx" for n in NAMES)
    assert all((tmp_path / f"{n}.onnx").read_bytes() != old[n] for n in NAMES)
