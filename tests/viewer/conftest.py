"""Fixtures for viewer tests: a headless EGL context, an Xvfb display, an output folder."""
from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
OUT_DIR = Path(__file__).resolve().parent / "_out"   # images saved for inspection (git-ignored)


@pytest.fixture(scope="session")
def out_dir() -> Path:
    OUT_DIR.mkdir(exist_ok=True)
    return OUT_DIR


@pytest.fixture(scope="session")
def gl_ctx():
    """A standalone EGL context (no display needed); skips when EGL is unavailable."""
    from viewer.context import ContextError, create_headless_context

    try:
        ctx = create_headless_context()
    except ContextError as e:
        pytest.skip(str(e))
    yield ctx
    ctx.release()


@pytest.fixture(autouse=True)
def _gl_ctx_current(request):
    """Make the shared context current before each test that uses it: a test that runs a command in
    process (``view --screenshot``) creates and releases a context of its own, which leaves none current."""
    if "gl_ctx" in request.fixturenames:
        request.getfixturevalue("gl_ctx").__enter__()
    yield


@pytest.fixture(scope="session")
def xvfb_env():
    """An environment with DISPLAY set to a fresh Xvfb, for subprocesses; skips when Xvfb is missing."""
    from viewer.xvfb import Xvfb, XvfbUnavailable

    try:
        server = Xvfb("1280x800x24", timeout_s=10.0)
    except XvfbUnavailable as e:
        pytest.skip(str(e))
    with server:
        yield server.env()
