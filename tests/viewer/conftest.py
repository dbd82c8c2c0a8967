"""Fixtures for viewer tests: a headless EGL context, an Xvfb display, an output folder."""
from __future__ import annotations

import os
import shutil
import subprocess
import time
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


@pytest.fixture(scope="session")
def xvfb_env():
    """Start ``Xvfb`` on a free display (it picks one itself via -displayfd) and return an
    environment with DISPLAY set, for subprocesses. Skips when Xvfb is missing or fails."""
    exe = shutil.which("Xvfb")
    if exe is None:
        pytest.skip("Xvfb is not installed (apt-get install xvfb)")
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen([exe, "-displayfd", str(write_fd), "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
                            pass_fds=(write_fd,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write_fd)
    number = b""
    deadline = time.monotonic() + 10.0
    os.set_blocking(read_fd, False)
    while time.monotonic() < deadline and not number.endswith(b"\n") and proc.poll() is None:
        try:
            number += os.read(read_fd, 16)
        except BlockingIOError:
            time.sleep(0.05)
    os.close(read_fd)
    if not number.strip().isdigit():
        proc.kill()
        proc.wait()
        pytest.skip("Xvfb did not start")
    env = dict(os.environ, DISPLAY=f":{number.decode().strip()}")
    yield env
    proc.terminate()
    try:
        proc.wait(timeout=5)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
