"""lmm.data.atomic: whole-file outputs appear complete or not at all."""
import os

import pytest

from lmm.data.atomic import atomic_write, write_bytes_atomic, write_text_atomic
from lmm.data.jsonio import json_safe, write_json


def test_atomic_write_replaces_only_on_success(tmp_path):
    target = tmp_path / "sub" / "out.txt"
    write_text_atomic(target, "first\n")
    assert target.read_text() == "first\n"
    with pytest.raises(RuntimeError):
        with atomic_write(target, "w") as f:
            f.write("half")
            raise RuntimeError("killed mid-write")
    assert target.read_text() == "first\n"
    assert sorted(os.listdir(target.parent)) == ["out.txt"]   # no temporary file left behind


def test_atomic_write_bytes_and_bad_mode(tmp_path):
    assert write_bytes_atomic(tmp_path / "b.bin", b"\x00\x01").read_bytes() == b"\x00\x01"
    with pytest.raises(ValueError):
        with atomic_write(tmp_path / "x", "a"):
            pass


def test_atomic_write_into_read_only_folder_raises_and_leaves_nothing(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        if os.access(folder, os.W_OK):  # root ignores permissions
            pytest.skip("running as a user that can write anywhere")
        with pytest.raises(OSError):
            write_text_atomic(folder / "x.json", "{}")
    finally:
        folder.chmod(0o700)
    assert list(folder.iterdir()) == []


def test_json_safe_and_write_json(tmp_path):
    import numpy as np

    value = {"a": np.float32(1.5), "b": float("nan"), "c": np.arange(3), "d": [np.inf, True, np.bool_(False)],
             "e": tmp_path}
    assert json_safe(value) == {"a": 1.5, "b": None, "c": [0, 1, 2], "d": [None, True, False], "e": str(tmp_path)}
    path = write_json(tmp_path / "o.json", value)
    assert path.read_text().startswith("{") and "NaN" not in path.read_text()


def test_errors_name_the_target_not_the_temporary_file(tmp_path, monkeypatch):
    import errno

    from lmm.data import atomic

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    target = tmp_path / "m.json"
    with pytest.raises(OSError) as e:
        with atomic_write(target, "w") as f:
            f.write("x")
            full()
    assert e.value.errno == errno.ENOSPC and e.value.filename == str(target)
    monkeypatch.setattr(atomic.os, "replace", lambda a, b: (_ for _ in ()).throw(
        PermissionError(errno.EROFS, "Read-only file system", str(a), None, str(b))))
    with pytest.raises(PermissionError) as e:
        write_text_atomic(target, "{}")
    assert e.value.filename == str(target) and not target.exists() and list(tmp_path.iterdir()) == []


def test_check_writable(tmp_path):
    from lmm.data.atomic import check_writable

    check_writable(tmp_path / "new" / "out.json")  # creates the folder, leaves no file
    assert (tmp_path / "new").is_dir() and list((tmp_path / "new").iterdir()) == []
    with pytest.raises(IsADirectoryError) as e:
        check_writable(tmp_path)
    assert e.value.filename == str(tmp_path)
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(NotADirectoryError, match="is a file, not a folder") as e:
        check_writable(blocker / "sub" / "out.json")
    assert e.value.filename == str(blocker / "sub" / "out.json")
