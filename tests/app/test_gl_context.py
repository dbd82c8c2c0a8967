"""A studio that cannot create its OpenGL context (issue 36): on a display that answers but has no GLX, or
with a graphics driver that cannot be loaded, dearpygui (GLFW) aborted the process (``glfwSetWindowPos:
Assertion 'window != NULL' failed``, exit 134) after Mesa's own error lines; now one line naming the
display and the reason, exit 1."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def display_without_glx():
    """``:N`` of an Xvfb started with its GLX extension turned off."""
    exe = shutil.which("Xvfb")
    if exe is None:
        pytest.skip("no Xvfb")
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen([exe, "-displayfd", str(write_fd), "-screen", "0", "800x600x24", "-nolisten", "tcp",
                             "-extension", "GLX"], pass_fds=(write_fd,), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    os.close(write_fd)
    try:
        with os.fdopen(read_fd) as f:
            number = f.readline().strip()
        if not number:
            pytest.skip("Xvfb did not start")
        yield f":{number}"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def studio(display: str, config: Path, **extra) -> subprocess.CompletedProcess:
    env = {**os.environ, "DISPLAY": display, "PYTHONPATH": str(ROOT), "LMM_STUDIO_CONFIG": str(config), **extra}
    env.pop("WAYLAND_DISPLAY", None)
    return subprocess.run([sys.executable, "-m", "app.cli", "--frames", "1", "--no-lmm", "--no-physics"], env=env,
                          capture_output=True, text=True, timeout=120)


def assert_one_line(r: subprocess.CompletedProcess, display: str, reason: str) -> None:
    assert r.returncode == 1, (r.returncode, r.stderr[-2000:])
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("lmm-studio: error: cannot create an OpenGL context on the display "), lines[0]
    assert repr(display) in lines[0] and reason in lines[0], lines[0]


def test_a_display_without_glx_is_one_line_and_exit_1(display_without_glx, tmp_path):
    r = studio(display_without_glx, tmp_path)
    assert_one_line(r, display_without_glx, "glXChooseFBConfig failed")
    assert not (tmp_path / "layout.ini.bad").exists()   # not taken for a layout that crashed the studio


def test_a_driver_that_cannot_be_loaded_is_one_line_and_exit_1(xvfb_display, tmp_path):
    r = studio(xvfb_display, tmp_path, LIBGL_ALWAYS_SOFTWARE="1", GALLIUM_DRIVER="nonexistent")
    assert_one_line(r, xvfb_display, "cannot create context")
