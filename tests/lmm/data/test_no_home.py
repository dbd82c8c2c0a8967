"""No home folder (issue 36): a uid with no passwd entry and HOME unset gave "internal error:
RuntimeError: Could not determine home directory"; now the cache and the config go to the stated
fallback, ``$TMPDIR/lmm-studio-home-UID`` (lmm.data.cache.home_dir)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]

# the uid's passwd entry removed (what a container's unnamed uid sees), then the command line
NO_PASSWD = ("import pwd, sys\n"
             "def missing(uid):\n    raise KeyError(uid)\n"
             "pwd.getpwuid = missing\n"
             "from app.cli import main\nsys.exit(main(sys.argv[1:]))\n")


def test_no_home_folder_falls_back_to_the_stated_place(tmp_path):
    env = {k: v for k, v in os.environ.items()
           if k not in ("HOME", "LMM_STUDIO_CACHE", "XDG_CACHE_HOME", "LMM_STUDIO_CONFIG", "XDG_CONFIG_HOME")}
    env.update(PYTHONPATH=str(ROOT), PYTHONDONTWRITEBYTECODE="1", TMPDIR=str(tmp_path))
    r = subprocess.run([sys.executable, "-c", NO_PASSWD, "build-db", "--manifest",
                        str(ROOT / "tests" / "corpus" / "good" / "manifest.json"), "--quiet", "--no-checks",
                        "--jobs", "1"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    home = tmp_path / f"lmm-studio-home-{os.getuid()}"
    assert str(home / ".cache" / "lmm-studio") in r.stdout, r.stdout
    shutil.rmtree(home, ignore_errors=True)


def test_the_studio_config_falls_back_too(monkeypatch, tmp_path):
    import pwd

    from app.layout_files import user_config_dir

    for name in ("HOME", "LMM_STUDIO_CONFIG", "XDG_CONFIG_HOME"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr(pwd, "getpwuid", lambda uid: (_ for _ in ()).throw(KeyError(uid)))
    import tempfile
    monkeypatch.setattr(tempfile, "tempdir", None)
    assert user_config_dir() == tmp_path / f"lmm-studio-home-{os.getuid()}" / ".config" / "lmm-studio"
