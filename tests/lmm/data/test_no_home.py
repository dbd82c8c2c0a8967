"""No home folder (issue 36): a uid with no passwd entry and HOME unset gave "internal error:
RuntimeError: Could not determine home directory"; now the cache and the config go to the stated
fallback, ``$TMPDIR/lmm-studio-home-UID`` (lmm.data.cache.home_dir). The commands' side (build-db and run
writing their cache there, nothing else touched) is in the corpus: tests/corpus/state_cases.py."""
from __future__ import annotations

import os


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
