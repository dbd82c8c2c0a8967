"""A studio that cannot open its window (issue 36): a DISPLAY no X server answers at aborted inside
dearpygui (GLFW's assertion, exit 134); now one line naming the display, exit 1."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_a_dead_display_is_one_line_and_exit_1(tmp_path):
    env = {**os.environ, "DISPLAY": ":77", "PYTHONPATH": str(ROOT), "LMM_STUDIO_CONFIG": str(tmp_path)}
    env.pop("WAYLAND_DISPLAY", None)
    r = subprocess.run([sys.executable, "-m", "app.cli", "--frames", "1"], env=env, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 1, (r.returncode, r.stderr[-2000:])
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "':77'" in lines[0] and "error" in lines[0], r.stderr
