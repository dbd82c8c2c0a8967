"""Fixtures for the studio tests.

GUI tests start ``Xvfb`` on a free display and run the real studio in a subprocess (dearpygui aborts
the whole process on some errors, and a test must survive that), with ``LMM_STUDIO_CONFIG`` and
``LMM_STUDIO_CACHE`` in temporary folders. The studio takes a ``--script`` of timed actions and writes
a ``--dump-state`` JSON at exit, which the tests assert on. They skip cleanly where Xvfb is missing.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from studio_testutil import CORPUS, ROOT  # noqa: F401  (pytest puts this folder on sys.path)


@pytest.fixture(scope="session")
def xvfb_display():
    """``:N`` of a fresh ``Xvfb -screen 0 1920x1080x24`` on a free display; skips without Xvfb."""
    from viewer.xvfb import Xvfb, XvfbUnavailable

    try:
        server = Xvfb("1920x1080x24")
    except XvfbUnavailable as e:
        pytest.skip(str(e))
    with server:
        yield server.display


@pytest.fixture(scope="session")
def studio_cache(tmp_path_factory):
    """One database cache for every studio run of the session (the first run builds it)."""
    return tmp_path_factory.mktemp("studio-cache")


@pytest.fixture(scope="session")
def lmm_weights(tmp_path_factory):
    """LMM weights for the studio: the shipped ones when they fit the database, else a tiny set trained
    here (needs torch), else None (the studio then runs MM only and the LMM checks are skipped)."""
    import numpy as np

    from lmm.data.build import load_or_build
    from lmm.features import build_features

    db, _ = load_or_build()
    features = build_features(db)
    try:
        from lmm.learned import DEFAULT_WEIGHTS, LMMNetworks

        LMMNetworks.load(DEFAULT_WEIGHTS, db, features)
        return str(DEFAULT_WEIGHTS)
    except Exception:
        pass
    try:
        import torch  # noqa: F401
        from lmm.offline import training as T
    except Exception:
        return None
    out = tmp_path_factory.mktemp("studio-weights")
    r = T.Recipe(decompressor=T.StageSettings(20, 32, 2e-3), stepper=T.StageSettings(10, 8, 2e-3),
                 projector=T.StageSettings(10, 32, 2e-3), stepper_window=6, hidden=64, threads=1)
    T.train_pipeline(db, features, T.NETWORKS, r, out, frames=np.arange(3000), quiet=True)
    return str(out / "default.npz")


class StudioRun:
    """One finished studio subprocess: return code, output and the state dump."""

    def __init__(self, rc: int, stdout: str, stderr: str, dump: dict | None, config: Path, workdir: Path):
        self.rc, self.stdout, self.stderr, self.dump = rc, stdout, stderr, dump
        self.config, self.workdir = config, workdir

    def __repr__(self):
        return f"StudioRun(rc={self.rc}, stderr={self.stderr[-2000:]!r})"


@pytest.fixture
def run_studio(xvfb_display, studio_cache, tmp_path):
    """``run_studio(*args, script=[...], config=None, timeout=...) -> StudioRun``."""

    def run(*args, script=None, config: Path | None = None, timeout: float = 150.0, env_extra=None) -> StudioRun:
        config = config or (tmp_path / "config")
        config.mkdir(parents=True, exist_ok=True)
        dump = tmp_path / f"dump-{time.monotonic_ns()}.json"
        cmd = [sys.executable, "-m", "app.cli", *map(str, args), "--dump-state", str(dump), "--no-gamepads"]
        if script is not None:
            script_path = tmp_path / f"script-{time.monotonic_ns()}.json"
            script_path.write_text(json.dumps({"actions": script}))
            cmd += ["--script", str(script_path)]
        # every run checks what the tick worker prepared for a frame against the GUI thread's own (app.prepared)
        env = dict(os.environ, DISPLAY=xvfb_display, LMM_STUDIO_CONFIG=str(config),
                   LMM_STUDIO_CACHE=str(studio_cache), PYTHONPATH=str(ROOT), LP_NUM_THREADS="0",
                   LMM_STUDIO_CHECK_PREPARED="1")
        env.update(env_extra or {})
        proc = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=timeout)
        data = json.loads(dump.read_text()) if dump.exists() else None
        if data is not None and "prepared" in data:
            assert data["prepared"]["checked"] and not data["prepared"]["mismatches"], data["prepared"]
        return StudioRun(proc.returncode, proc.stdout, proc.stderr, data, config, tmp_path)

    return run


@pytest.fixture(scope="module")
def dbf(db):
    """The default database (the session's) with features of its own per module (tests change weights)."""
    from lmm.features import build_features

    return db, build_features(db)
